//! `experiment extended-dig-check`: single digs of the extended experiment's start poses, checked.

use super::*;

/// One start of [`extended_dig_check`]: the simulator and the dig model from the same start on the
/// extended bench (the simulator's true pre-dig section for both).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct DigCheck {
    /// Machine x in the world (the crest of the face is at `4 - machine_x_m` m from the swing axis).
    pub machine_x_m: f64,
    /// The start tip `[r, z, bucket_abs_deg]` on the surface, base frame.
    pub start: [f64; 3],
    /// Where the simulated dig began Pre-Dig (after Boom-Down when `boom_down`), `[r, z]`, m.
    pub sim_predig_start: [f64; 2],
    /// Lowest tip z: simulator, dig model, m.
    pub min_tip_z_m: [f64; 2],
    /// Swept volume: simulator, dig model, m^3.
    pub swept_m3: [f64; 2],
    /// Dig time (Pre-Dig to Done): simulator, dig model, s.
    pub time_s: [f64; 2],
    /// The simulator's bucket content at the end, m^3.
    pub sim_bucket_m3: f64,
    /// Mean soil force magnitude over the Pre-Dig and Dig samples in contact: simulator, and the dig
    /// model's soil model at the simulator's pose, velocities, cut terrain and content (open loop), N.
    pub mean_soil_force_n: [f64; 2],
    /// Mean `(F_x, F_z)` of the same samples: simulator, open-loop model, N.
    pub mean_soil_fxz_n: [[f64; 2]; 2],
    /// End reasons: simulator, dig model.
    pub end: [String; 2],
}

/// Digs from a grid of starts on the extended bench (machine at world x 0, -1.5, -3: crest at 4, 5.5,
/// 7 m) in the simulator and in the nominal dig model from the same start over the simulator's true
/// section: where their tip paths part (the model once predicted the tip 0.5-1.2 m deeper than
/// the simulator took it for starts high on the face). With `boom_down` the simulated dig starts
/// [`controller::session::planned::APPROACH_HEIGHT_M`] above the start with Autodig's Boom-Down, as in a session;
/// the model starts in Pre-Dig on the start as the refined planner evaluates it.
///
/// # Errors
/// Simulator, kinematics, Autodig or dig-model errors.
pub fn extended_dig_check(boom_down: bool) -> anyhow::Result<Vec<DigCheck>> {
    use anyhow::Context as _;
    use planner::autodig::{Autodig, AutodigInputs, Stage};
    use planner::dig_model::{DigModel, DigSite, DigStart};
    use planner::kinematics::{BucketPose, Joint, Kinematics, MachinePose};
    use planner::terrain::SweptVolume;
    use vcan_sim::scenario::Scenario;
    let base = {
        let mut sim = SimConfig::load::<&str>(None, None, Some(1), &[])?;
        sim.scenario = Scenario::from_toml_str_named(
            crate::demo::EXTENDED_BENCH_TOML,
            "config/bench_extended.toml",
        )
        .context("built-in extended bench")?;
        sim
    };
    let kin = Kinematics::new(&base.machine)?;
    let model = DigModel::nominal()?;
    let maps = AutodigMaps::builtin()?;
    let strokes = Joint::ALL.map(|j| kin.stroke(j));
    let mut ad_cfg = model.config().autodig;
    ad_cfg.relief_pressure_pa = [base.machine.hydraulics.relief_pressure_pa; 3];
    ad_cfg.perception.bucket_capacity_m3 = base.machine.bucket.capacity_m3;
    let mut rows = Vec::new();
    for machine_x_m in [0.0, -1.5, -3.0] {
        let crest = 4.0 - machine_x_m;
        let pose = MachinePose {
            x_m: machine_x_m,
            y_m: 0.0,
            heading_rad: 0.0,
        };
        for dr in [-0.8, 0.0, 0.6, 1.2, 1.8] {
            for bucket_abs_deg in [-60.0, -90.0, -120.0] {
                let mut sim = base.clone();
                sim.scenario.start.x_m = machine_x_m;
                let plant0 = sim.build()?;
                let profile = plant0.world.terrain.section(&pose, 0.0, 0.5, 12.0, 0.05)?;
                let r = crest + dr;
                let z = profile.height_at(r)?;
                let start = BucketPose {
                    x_m: r,
                    z_m: z,
                    bucket_abs_rad: f64::to_radians(bucket_abs_deg),
                };
                let Ok(q) = kin.inverse(&start) else {
                    continue;
                };
                if kin.cylinder_lengths(&q).is_err() {
                    continue;
                }
                let site = DigSite::new(profile.clone(), -2.0)?;
                let Ok(pred) = model.predict(&DigStart::Joints(q), &site) else {
                    continue;
                };
                let q_sim = if boom_down {
                    controller::session::planned::approach_joints(
                        &kin,
                        q,
                        controller::session::planned::APPROACH_HEIGHT_M,
                    )
                } else {
                    q
                };
                sim.scenario.start.boom_deg = q_sim.boom_rad.to_degrees();
                sim.scenario.start.stick_deg = q_sim.stick_rad.to_degrees();
                sim.scenario.start.bucket_deg = q_sim.bucket_rad.to_degrees();
                sim.scenario.start.swing_deg = 0.0;
                let mut plant = sim.build()?;
                let mut swept = SweptVolume::new(profile.clone(), base.machine.bucket.width_m)?;
                let mut autodig = Autodig::starting_in(
                    ad_cfg,
                    maps.clone(),
                    if boom_down {
                        Stage::BoomDown
                    } else {
                        Stage::PreDig
                    },
                )?;
                let mut min_z = f64::INFINITY;
                let mut predig_start = None;
                let mut t_predig = 0.0;
                let mut end = None;
                let (mut f_sum, mut fm_sum, mut n_f) = (0.0, 0.0, 0usize);
                let (mut fxz, mut fxz_m) = ([0.0; 2], [0.0; 2]);
                let mut t_done = f64::NAN;
                for step in 0..4000usize {
                    let t = step as f64 * crate::demo::PERIOD_S;
                    let rd = plant.read_sensors();
                    let qn = plant.joint_angles();
                    let tip = kin.forward(&qn);
                    let mut ext = [0.0; 3];
                    for (j, joint) in Joint::ALL.iter().enumerate() {
                        let len = kin.cylinder_length(*joint, qn.to_vector()[j])?;
                        ext[j] =
                            ((len - strokes[j].0) / (strokes[j].1 - strokes[j].0)).clamp(0.0, 1.0);
                    }
                    let in_dig = predig_start.is_some();
                    let inputs = AutodigInputs {
                        joint_rad: [qn.boom_rad, qn.stick_rad, qn.bucket_rad],
                        head_pressure_pa: rd.head_pa,
                        rod_pressure_pa: rd.rod_pa,
                        extension_fraction: ext,
                        swept_volume_m3: if in_dig {
                            swept.update(tip.x_m, tip.z_m).ok()
                        } else {
                            Some(0.0)
                        },
                        bucket_depth_m: swept.depth_m(tip.x_m, tip.z_m).ok(),
                    };
                    let out = autodig.step(&inputs, t)?;
                    if predig_start.is_none() && out.stage != Stage::BoomDown {
                        predig_start = Some([tip.x_m, tip.z_m]);
                        t_predig = t;
                        swept = SweptVolume::new(profile.clone(), base.machine.bucket.width_m)?;
                    }
                    if predig_start.is_some() {
                        min_z = min_z.min(tip.z_m);
                        if matches!(out.stage, Stage::PreDig | Stage::Dig) {
                            let truth = plant.true_state();
                            let fs = truth.soil_force_n;
                            if fs[0].hypot(fs[1]) > 1.0 {
                                let now =
                                    plant.world.terrain.section(&pose, 0.0, 0.5, 12.0, 0.05)?;
                                let v = [0, 1, 2].map(|i| plant.hydraulics.actuators[i].velocity);
                                let fm = model.soil_force_at(
                                    &qn,
                                    v,
                                    &now,
                                    plant.contact.content.volume_m3,
                                )?;
                                f_sum += fs[0].hypot(fs[1]);
                                fm_sum += fm.fx_n.hypot(fm.fz_n);
                                fxz[0] += fs[0];
                                fxz[1] += fs[1];
                                fxz_m[0] += fm.fx_n;
                                fxz_m[1] += fm.fz_n;
                                n_f += 1;
                            }
                        }
                    }
                    let command = out.command;
                    if out.stage == Stage::Done {
                        end = out.end_reason;
                        t_done = t - t_predig;
                        break;
                    }
                    for _ in 0..10 {
                        plant.step([command[0], command[1], command[2], 0.0, 0.0, 0.0]);
                    }
                }
                let n = n_f.max(1) as f64;
                let s = &pred.summary;
                rows.push(DigCheck {
                    machine_x_m,
                    start: [r, z, bucket_abs_deg],
                    sim_predig_start: predig_start.unwrap_or([f64::NAN; 2]),
                    min_tip_z_m: [min_z, s.min_tip_z_m],
                    swept_m3: [swept.volume_m3(), s.swept_volume_m3],
                    time_s: [t_done, s.time_s],
                    sim_bucket_m3: plant.contact.content.volume_m3,
                    mean_soil_force_n: [f_sum / n, fm_sum / n],
                    mean_soil_fxz_n: [[fxz[0] / n, fxz[1] / n], [fxz_m[0] / n, fxz_m[1] / n]],
                    end: [
                        end.map_or_else(|| "none".to_owned(), |e| format!("{e:?}")),
                        format!("{:?}", s.end),
                    ],
                });
            }
        }
    }
    Ok(rows)
}

pub(super) fn extended_dig_check_report() -> anyhow::Result<String> {
    use std::fmt::Write as _;
    let mut s = String::new();
    for boom_down in [false, true] {
        let rows = extended_dig_check(boom_down)?;
        let _ = writeln!(
            s,
            "\nSimulator vs dig model on the extended bench ({}; model from Pre-Dig on the start)\n",
            if boom_down {
                "simulator: Boom-Down from 0.8 m above"
            } else {
                "simulator: Pre-Dig on the start"
            }
        );
        let _ = writeln!(
            s,
            "| machine x | start r, z, bucket | sim Pre-Dig r, z | min z sim / model | swept sim / model | bucket | time sim / model | |F| sim / model (kN) | Fx, Fz sim | Fx, Fz model | end sim / model |\n|---|---|---|---|---|---|---|---|---|---|---|"
        );
        for r in &rows {
            let _ = writeln!(
                s,
                "| {:.1} | {:.2}, {:.2}, {:.0} | {:.2}, {:.2} | {:.2} / {:.2} | {:.2} / {:.2} | {:.2} | {:.1} / {:.1} | {:.1} / {:.1} | {:.1}, {:.1} | {:.1}, {:.1} | {} / {} |",
                r.machine_x_m,
                r.start[0],
                r.start[1],
                r.start[2],
                r.sim_predig_start[0],
                r.sim_predig_start[1],
                r.min_tip_z_m[0],
                r.min_tip_z_m[1],
                r.swept_m3[0],
                r.swept_m3[1],
                r.sim_bucket_m3,
                r.time_s[0],
                r.time_s[1],
                r.mean_soil_force_n[0] * 1e-3,
                r.mean_soil_force_n[1] * 1e-3,
                r.mean_soil_fxz_n[0][0] * 1e-3,
                r.mean_soil_fxz_n[0][1] * 1e-3,
                r.mean_soil_fxz_n[1][0] * 1e-3,
                r.mean_soil_fxz_n[1][1] * 1e-3,
                r.end[0],
                r.end[1]
            );
        }
    }
    Ok(s)
}
