//! Data sufficiency: whether the measured sessions hold enough to name anything. A session is read
//! as one record per dig index, which a machine that never finishes a dig still produces (a work
//! cycle retried, faulted, stuck short of the soil); such records carry hydraulics but no dig, no
//! soil force and no weighing. The analysis is refused below [`MIN_COMPLETED_DIGS`] completed digs,
//! and warned about below [`RECOMMENDED_COMPLETED_DIGS`]; after the analysis, signals with too few
//! held-out samples, or with all their samples on one side of the training/held-out split, are
//! warned about by name with what to record.

use crate::effects::CandidateEffect as _;
use crate::fit::AnalysisResult;
use crate::greybox::PreparedRecord;
use crate::{Candidate, DiscrepancyError, LoadTag, Result, Sample, Signal, StageTag};

/// Fewer completed digs than this: the analysis is refused.
pub const MIN_COMPLETED_DIGS: usize = 1;

/// Fewer completed digs than this: the analysis runs with a warning.
pub const RECOMMENDED_COMPLETED_DIGS: usize = 6;

/// A signal with fewer held-out independent samples (samples over the decorrelation factor) than
/// this is warned about: its candidates are scored on too little.
pub const MIN_INDEPENDENT_SAMPLES: f64 = 30.0;

/// Whether a record holds a completed dig: the Autodig reached Capture and the work cycle went on
/// to weigh or carry the load (a dig that ended in a fault or was abandoned does not).
pub fn is_completed_dig(samples: &[Sample]) -> bool {
    let Some(last_capture) = samples.iter().rposition(|s| s.stage == StageTag::Capture) else {
        return false;
    };
    samples.iter().any(|s| s.stage == StageTag::Dig)
        && samples[last_capture..]
            .iter()
            .any(|s| matches!(s.load, LoadTag::Weighing | LoadTag::Loaded))
}

/// Checks the records before an analysis: the warnings to report.
///
/// # Errors
/// [`DiscrepancyError::NotEnoughData`] with fewer than [`MIN_COMPLETED_DIGS`] completed digs,
/// saying how many records were read, how many digs completed and what to record.
pub fn check_records(records: &[PreparedRecord]) -> Result<Vec<String>> {
    let completed = records
        .iter()
        .filter(|r| is_completed_dig(&r.samples))
        .count();
    let soil_samples = records
        .iter()
        .flat_map(|r| &r.samples)
        .filter(|s| s.stage == StageTag::Dig)
        .count();
    if completed < MIN_COMPLETED_DIGS {
        return Err(DiscrepancyError::NotEnoughData(format!(
            "{} work-cycle record(s) read, {completed} with a completed dig (Autodig through \
             Dig and Capture to the weighing or the swing to the dump; {soil_samples} samples in \
             the Dig stage): the machine never completed its work, so there is nothing to compare \
             the model with; record a session in which the machine completes digs (at least \
             {RECOMMENDED_COMPLETED_DIGS}; no fault, the bucket reaching the soil)",
            records.len()
        )));
    }
    let mut warnings = Vec::new();
    if completed < records.len() {
        warnings.push(format!(
            "{} of {} work-cycle records hold no completed dig (no Capture followed by the \
             weighing or the swing to the dump): the machine stalled or retried; they are \
             analysed for the hydraulics and forces they carry, but the soil and payload \
             relations rest on the completed digs alone",
            records.len() - completed,
            records.len()
        ));
    }
    if completed < RECOMMENDED_COMPLETED_DIGS {
        warnings.push(format!(
            "only {completed} completed dig(s): too few to name soil and payload effects \
             reliably; record at least {RECOMMENDED_COMPLETED_DIGS} (16 recommended)"
        ));
    }
    Ok(warnings)
}

/// What to record to get more samples of a signal.
fn what_to_record(sig: Signal) -> &'static str {
    match sig.index() {
        0..=4 => "more work cycles with the valves moving",
        5..=7 => "more swings and returns with an empty bucket in free air",
        8..=9 => "more digs in which the bucket cuts the soil at speed (Dig stage)",
        10 => {
            "work cycles that press a joint into its end stop at rest (the bucket curled in Capture)"
        }
        _ => "more digs that fill the bucket and weigh it (Weigh after the dig)",
    }
}

/// Warnings about signals after an analysis: no samples at all (the candidates acting on the signal
/// are not checked), too few held-out independent samples (they are named from too little), or all
/// samples on one side of the split.
pub fn signal_warnings(result: &AnalysisResult) -> Vec<String> {
    Signal::ALL
        .iter()
        .filter_map(|sig| {
            let j = sig.index();
            signal_warning(
                *sig,
                result.rms.get(j).map_or(0, |m| m.samples),
                result.train_samples.get(j).copied().unwrap_or(0),
                result.kappa.get(j).copied().unwrap_or(1.0),
            )
        })
        .collect()
}

/// The warning about one signal with `test` held-out and `train` training samples and the
/// decorrelation factor `kappa` (samples per independent one), if any.
fn signal_warning(sig: Signal, test: usize, train: usize, kappa: f64) -> Option<String> {
    let j = sig.index();
    let candidates: Vec<&str> = Candidate::ALL
        .iter()
        .filter(|c| c.groups().contains(j))
        .map(|c| c.name())
        .collect();
    let kappa = if kappa.is_finite() {
        kappa.max(1.0)
    } else {
        1.0
    };
    if test + train == 0 {
        // A resolver offset that keeps the bucket short of its stop, say: the sessions hold no
        // end-stop sample, and nothing else shows the offset.
        Some(format!(
            "{}: no samples in the measured sessions, so {} cannot be checked; record {}",
            sig.name(),
            if candidates.is_empty() {
                "the signal".to_string()
            } else {
                candidates.join(", ")
            },
            what_to_record(sig)
        ))
    } else if test == 0 || train == 0 {
        Some(format!(
            "{}: all {} samples fall in the {} digs: it cannot be both fitted and judged \
             ({}); record {}",
            sig.name(),
            test + train,
            if test == 0 { "training" } else { "held-out" },
            candidates.join(", "),
            what_to_record(sig)
        ))
    } else if (test as f64) / kappa < MIN_INDEPENDENT_SAMPLES {
        Some(format!(
            "{}: {test} held-out samples, about {:.0} independent (< {MIN_INDEPENDENT_SAMPLES:.0}): \
             {} are judged on too little; record {}",
            sig.name(),
            test as f64 / kappa,
            candidates.join(", "),
            what_to_record(sig)
        ))
    } else {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(stage: StageTag, load: LoadTag) -> Sample {
        Sample {
            stage,
            load,
            ..Sample::default()
        }
    }

    #[test]
    fn a_dig_is_completed_only_through_capture_to_the_weighing() {
        use LoadTag::{EmptyFreeAir as Air, InSoil, Weighing};
        let full = [
            sample(StageTag::Outside, Air),
            sample(StageTag::BoomDown, Air),
            sample(StageTag::PreDig, InSoil),
            sample(StageTag::Dig, InSoil),
            sample(StageTag::Capture, InSoil),
            sample(StageTag::Outside, Weighing),
        ];
        assert!(is_completed_dig(&full));
        // Faulted in Capture: no weighing after it.
        assert!(!is_completed_dig(&full[..5]));
        // Never reached the soil: Boom-Down again and again.
        let stuck: Vec<Sample> = (0..50)
            .map(|k| {
                sample(
                    if k % 2 == 0 {
                        StageTag::BoomDown
                    } else {
                        StageTag::Outside
                    },
                    Air,
                )
            })
            .collect();
        assert!(!is_completed_dig(&stuck));
        assert!(!is_completed_dig(&[]));
    }

    /// The case: a session in which no dig completed (the work cycle retried Boom-Down
    /// over and over) read as 48 records is refused, saying what is missing.
    #[test]
    fn a_session_without_a_completed_dig_is_refused() {
        let machine = planner::machine::MachineConfig::default_machine().unwrap();
        let params = crate::GreyBoxParams::from_machine(&machine);
        let record = |index: u32, completed: bool| {
            let samples = (0..300)
                .map(|k| {
                    let (stage, load) = match k {
                        100..150 => (StageTag::BoomDown, LoadTag::EmptyFreeAir),
                        150..200 if completed => (StageTag::Dig, LoadTag::InSoil),
                        200..250 if completed => (StageTag::Capture, LoadTag::InSoil),
                        250.. if completed => (StageTag::Outside, LoadTag::Weighing),
                        _ => (StageTag::Outside, LoadTag::EmptyFreeAir),
                    };
                    Sample {
                        time_s: f64::from(k) * crate::PERIOD_S,
                        angles_rad: [0.2, -1.5, -0.5],
                        stage,
                        load,
                        ..Sample::default()
                    }
                })
                .collect();
            let dig = crate::DigRecord {
                index,
                samples,
                section: None,
                lanes: Vec::new(),
            };
            PreparedRecord::new(&dig, &machine, &params).unwrap()
        };
        let stuck: Vec<PreparedRecord> = (0..48).map(|i| record(i, false)).collect();
        let e = check_records(&stuck).unwrap_err().to_string();
        assert!(
            e.contains("48 work-cycle record(s) read, 0 with a completed dig"),
            "{e}"
        );
        assert!(e.contains("record a session"), "{e}");
        let few: Vec<PreparedRecord> = (0..4).map(|i| record(i, i != 1)).collect();
        let warnings = check_records(&few).unwrap();
        assert_eq!(warnings.len(), 2, "{warnings:?}");
        assert!(warnings[0].contains("1 of 4 work-cycle records hold no completed dig"));
        assert!(warnings[1].contains("only 3 completed dig(s)"));
        let many: Vec<PreparedRecord> = (0..8).map(|i| record(i, true)).collect();
        assert!(check_records(&many).unwrap().is_empty());
    }

    /// A signal without a sample says which candidates go unchecked and what to record; one
    /// split to one side, or held out too thinly, says so; one with enough says nothing.
    #[test]
    fn signals_without_enough_samples_are_warned_about_by_name() {
        let none = signal_warning(Signal::StopAngle, 0, 0, 1.0).expect("warned");
        assert!(
            none.contains("stop_angle: no samples")
                && none.contains("resolver_offset cannot be checked")
                && none.contains("end stop"),
            "{none}"
        );
        let one_side = signal_warning(Signal::StopAngle, 0, 500, 1.0).expect("warned");
        assert!(
            one_side.contains("all 500 samples fall in the training digs"),
            "{one_side}"
        );
        let thin = signal_warning(Signal::StopAngle, 200, 500, 10.0).expect("warned");
        assert!(thin.contains("about 20 independent"), "{thin}");
        assert_eq!(signal_warning(Signal::StopAngle, 500, 500, 10.0), None);
        assert_eq!(signal_warning(Signal::StopAngle, 500, 500, f64::NAN), None);
    }
}
