//! `trace convert`: a wide CSV of decoded signals, or MCAP for Foxglove Studio and PlotJuggler.
//!
//! # CSV
//!
//! Columns: `timestamp_s` (the candump timestamp, seconds), `t_s` (seconds after the first frame),
//! then one column per DBC signal named `Message.Signal` in DBC order (physical units of the DBC:
//! rad, rad/s, Pa, %, m, m3; enums and counters as numbers), or only the `--signal` columns.
//! Values are forward-filled: a cell holds the latest value of its signal at the row's time, empty
//! before the first one and while the signal is "not available", "error" or out of range.
//!
//! - `--rows frame` (default): one row per frame of a project message (other frames add no row).
//! - `--rows step --step-ms 10`: one row per time step from the first frame, with the values the
//!   signals had at that time (zero-order hold), for tools that want a uniform time base.
//!
//! # MCAP
//!
//! One channel per message and source address, topic `/can/<Message>` (with `/sa_XX` appended for a
//! source address other than the DBC's), JSON-encoded messages described by a JSON Schema
//! (`jsonschema` schema encoding, `json` message encoding), so Foxglove and PlotJuggler plot the
//! fields directly. A message has every signal as a number (`null` when not valid), `<Signal>_name`
//! for signals with a DBC value table, `can_id`, and `error` (why [`Message::decode`] rejects it, or
//! `null`). Frames that are no project message (unknown ids, error frames) go to `/can/raw` (`id`,
//! `kind`, `dlc`, `data` hex, `interface`, `direction`). Log and publish time are the candump
//! timestamp in ns.
//!
//! Beside them the Foxglove view of the session ([`crate::view`], the topics the live stream
//! serves): the frames go through the controller's own estimator (`controller::step::estimate`), and at
//! each joint-angle frame `/tf` gets the machine's frames and `/signals` the pressures, joint angles,
//! the valve commands and the `ControllerStatus` fields the controller sent; `/scene` holds the
//! machine's links, `/log` a line at each change of activity or fault. A trace has no scans, so no
//! `/terrain`. Chunks are zstd-compressed, each followed by its message indexes (per channel, the
//! log time and offset of every message), and the summary lists the chunk indexes and statistics, so
//! a reader seeks by time and topic.

use std::collections::{BTreeMap, HashMap};
use std::fmt::Write as _;
use std::fs::File;
use std::io::{self, BufRead, BufWriter, Seek, Write};
use std::path::PathBuf;

use anyhow::Context as _;
use firmware_bridge::dbc;
use firmware_bridge::frame::{CanFrame, CanId, FrameKind};
use firmware_bridge::trace::{Direction, TraceRecord};
use firmware_bridge::{J1939Id, Message};

use super::input::{self, ReadSummary};
use super::signals::{self, SignalRef, SignalValue};
use super::view;
use super::{InputArgs, format_timestamp};

/// Output format.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Format {
    /// Wide CSV of decoded signals.
    Csv,
    /// MCAP: the decoded messages (JSON) and the Foxglove view (well-known schemas), zstd chunks.
    Mcap,
}

/// CSV row mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum Rows {
    /// One row per frame of a project message.
    #[default]
    Frame,
    /// One row per time step (`--step-ms`).
    Step,
}

/// `trace convert` arguments.
#[derive(Debug, Clone, clap::Args)]
pub struct ConvertArgs {
    /// The trace.
    #[command(flatten)]
    pub input: InputArgs,
    /// Output format.
    #[arg(long = "to", value_enum)]
    pub format: Format,
    /// Output file.
    #[arg(long)]
    pub out: PathBuf,
    /// CSV rows: per frame or per time step.
    #[arg(long, value_enum, default_value_t = Rows::Frame)]
    pub rows: Rows,
    /// CSV time step for `--rows step`, ms.
    #[arg(long, default_value_t = 10.0, value_name = "MS")]
    pub step_ms: f64,
    /// CSV columns: only these signals (`BoomAngle` or `Message.Signal`); repeatable.
    #[arg(long = "signal", value_name = "NAME")]
    pub signals: Vec<String>,
    /// MCAP: the machine file whose kinematics place the links (default: the built-in
    /// config/machine.toml).
    #[arg(long, value_name = "FILE")]
    pub machine: Option<PathBuf>,
}

/// Counts of a conversion.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct ConvertSummary {
    /// What the reader saw.
    pub read: ReadSummary,
    /// CSV rows or MCAP messages written (not counting `/can/raw` and the view).
    pub written: u64,
    /// MCAP: messages of the Foxglove view ([`crate::view`]) written.
    pub view_written: u64,
}

/// The CSV writer's state: the latest value of every column.
#[derive(Debug)]
struct CsvState {
    columns: Vec<SignalRef>,
    /// For each DBC signal column (all signals), its position in `columns`, if selected.
    position: Vec<Option<usize>>,
    values: Vec<f64>,
    first_ns: Option<u64>,
    next_step_ns: u64,
    line: String,
}

impl CsvState {
    fn new(columns: Vec<SignalRef>) -> Self {
        let mut position = vec![None; signals::all_signals().len()];
        for (i, c) in columns.iter().enumerate() {
            if let Some(p) = position.get_mut(c.column) {
                *p = Some(i);
            }
        }
        let values = vec![f64::NAN; columns.len()];
        Self {
            columns,
            position,
            values,
            first_ns: None,
            next_step_ns: 0,
            line: String::with_capacity(1024),
        }
    }

    fn header(&self) -> String {
        let mut h = String::from("timestamp_s,t_s");
        for c in &self.columns {
            h.push(',');
            h.push_str(&c.full_name());
        }
        h.push('\n');
        h
    }

    /// Updates the values from a frame; true if it touched a selected column.
    fn update(&mut self, frame: &CanFrame) -> bool {
        let Some((msg_index, desc)) = signals::message_of(frame) else {
            return false;
        };
        let data = frame.data();
        if data.len() != usize::from(desc.dlc) {
            return false;
        }
        let base = signals::first_column(msg_index);
        let mut touched = false;
        for (i, sig) in desc.signals.iter().enumerate() {
            if let Some(Some(pos)) = self.position.get(base + i) {
                let v = signals::decode_signal(sig, data)
                    .value()
                    .unwrap_or(f64::NAN);
                if let Some(slot) = self.values.get_mut(*pos) {
                    *slot = v;
                }
                touched = true;
            }
        }
        touched
    }

    fn write_row(&mut self, out: &mut dyn Write, timestamp_ns: u64) -> io::Result<()> {
        let first = self.first_ns.unwrap_or(timestamp_ns);
        self.line.clear();
        format_timestamp(timestamp_ns, &mut self.line);
        let rel_ns = timestamp_ns.saturating_sub(first);
        // Writing to a String cannot fail.
        let _ = write!(
            self.line,
            ",{}.{:09}",
            rel_ns / 1_000_000_000,
            rel_ns % 1_000_000_000
        );
        for v in &self.values {
            self.line.push(',');
            if v.is_finite() {
                let _ = write!(self.line, "{v}");
            }
        }
        self.line.push('\n');
        out.write_all(self.line.as_bytes())
    }
}

fn csv_columns(names: &[String]) -> anyhow::Result<Vec<SignalRef>> {
    if names.is_empty() {
        return Ok(signals::all_signals().to_vec());
    }
    names
        .iter()
        .map(|n| signals::resolve_signal(n).map_err(anyhow::Error::msg))
        .collect()
}

/// Writes the wide CSV of `input` to `out`.
///
/// # Errors
/// Bad signal names, a non-positive step, read errors (as [`input::for_each_record`]) and write errors.
pub fn to_csv<R: BufRead>(
    input: R,
    out: &mut dyn Write,
    rows: Rows,
    step_s: f64,
    signal_names: &[String],
    read: impl Into<input::ReadOptions>,
    diag: &mut dyn Write,
) -> anyhow::Result<ConvertSummary> {
    let step_ns = step_s * 1e9;
    if rows == Rows::Step && !(step_ns.is_finite() && step_ns >= 1.0) {
        anyhow::bail!("--step-ms must be positive");
    }
    let step_ns = step_ns as u64;
    let mut st = CsvState::new(csv_columns(signal_names)?);
    out.write_all(st.header().as_bytes())
        .context("writing the CSV header")?;
    let mut written = 0u64;
    let read = input::for_each_record(input, read, diag, |rec| {
        let is_first = st.first_ns.is_none();
        let first = *st.first_ns.get_or_insert(rec.timestamp_ns);
        match rows {
            Rows::Frame => {
                if st.update(&rec.frame) {
                    st.write_row(out, rec.timestamp_ns)?;
                    written += 1;
                }
            }
            Rows::Step => {
                if is_first {
                    st.next_step_ns = first;
                }
                // Rows strictly before this frame's time hold the values before it.
                while st.next_step_ns < rec.timestamp_ns {
                    st.write_row(out, st.next_step_ns)?;
                    written += 1;
                    st.next_step_ns = st.next_step_ns.saturating_add(step_ns);
                }
                st.update(&rec.frame);
            }
        }
        Ok(true)
    })?;
    if rows == Rows::Step && st.first_ns.is_some() {
        // The row at (or just after) the last frame shows the final values.
        st.write_row(out, st.next_step_ns)?;
        written += 1;
    }
    out.flush().context("writing the CSV")?;
    Ok(ConvertSummary {
        read,
        written,
        view_written: 0,
    })
}

/// JSON Schema of a message's MCAP payload.
pub fn json_schema(desc: &dbc::MessageDesc) -> String {
    let mut props = serde_json::Map::new();
    props.insert(
        "can_id".into(),
        serde_json::json!({"type": "string", "description": "29-bit id, hex"}),
    );
    props.insert(
        "error".into(),
        serde_json::json!({"type": ["string", "null"], "description": "why the receiver would reject the frame"}),
    );
    for sig in desc.signals {
        let description = if sig.unit.is_empty() {
            format!("factor {}, range [{}, {}]", sig.factor, sig.min, sig.max)
        } else {
            format!(
                "{}; factor {}, range [{}, {}]",
                sig.unit, sig.factor, sig.min, sig.max
            )
        };
        props.insert(
            sig.name.into(),
            serde_json::json!({"type": ["number", "null"], "description": description}),
        );
        if signals::value_name_in(desc, sig.name, sig.raw_min).is_some()
            || signals::value_name_in(desc, sig.name, sig.raw_max).is_some()
        {
            props.insert(
                format!("{}_name", sig.name),
                serde_json::json!({"type": ["string", "null"], "description": "DBC value table name"}),
            );
        }
    }
    serde_json::json!({
        "title": desc.name,
        "type": "object",
        "properties": props,
    })
    .to_string()
}

const RAW_SCHEMA: &str = r#"{"title":"CanFrame","type":"object","properties":{"id":{"type":"string","description":"CAN id, hex (3 digits 11-bit, 8 digits 29-bit)"},"kind":{"type":"string","enum":["data","remote","error","fd"]},"dlc":{"type":"integer"},"data":{"type":"string","description":"payload, hex"},"interface":{"type":"string"},"direction":{"type":["string","null"],"enum":["R","T",null]}}}"#;

fn push_json_number(out: &mut String, v: Option<f64>) {
    match v {
        Some(v) if v.is_finite() => {
            let _ = write!(out, "{v}");
        }
        _ => out.push_str("null"),
    }
}

fn push_json_string(out: &mut String, s: &str) {
    // serde_json escapes; a String serializer cannot fail.
    out.push_str(&serde_json::to_string(s).unwrap_or_else(|_| "\"\"".to_string()));
}

/// The JSON payload of a project message (see the module docs).
pub fn message_json(desc: &dbc::MessageDesc, frame: &CanFrame, out: &mut String) {
    out.clear();
    let data = frame.data();
    let _ = write!(out, "{{\"can_id\":\"{:08X}\"", frame.id().raw());
    let dlc_ok = data.len() == usize::from(desc.dlc);
    for sig in desc.signals {
        let value = if dlc_ok {
            signals::decode_signal(sig, data)
        } else {
            SignalValue::NotAvailable
        };
        let _ = write!(out, ",\"{}\":", sig.name);
        push_json_number(out, value.value());
        let has_table = signals::value_name_in(desc, sig.name, sig.raw_min).is_some()
            || signals::value_name_in(desc, sig.name, sig.raw_max).is_some();
        if has_table {
            let _ = write!(out, ",\"{}_name\":", sig.name);
            let name = dbc::decode_raw(sig, data)
                .ok()
                .and_then(|raw| signals::value_name_in(desc, sig.name, raw));
            match name {
                Some(n) => push_json_string(out, n),
                None => out.push_str("null"),
            }
        }
    }
    out.push_str(",\"error\":");
    match Message::decode(frame) {
        Ok(_) => out.push_str("null"),
        Err(e) => push_json_string(out, &e.to_string()),
    }
    out.push('}');
}

fn raw_json(rec: &TraceRecord, out: &mut String) {
    out.clear();
    let frame = &rec.frame;
    let (id, kind) = match (frame.kind(), frame.id()) {
        (FrameKind::Error, _) => (format!("{:08X}", frame.error_class()), "error"),
        (k, CanId::Standard(id)) => (format!("{id:03X}"), kind_name(k)),
        (k, CanId::Extended(id)) => (format!("{id:08X}"), kind_name(k)),
    };
    let _ = write!(
        out,
        "{{\"id\":\"{id}\",\"kind\":\"{kind}\",\"dlc\":{},\"data\":\"",
        frame.dlc()
    );
    if !frame.is_remote() {
        for b in frame.data() {
            let _ = write!(out, "{b:02X}");
        }
    }
    out.push_str("\",\"interface\":");
    push_json_string(out, &rec.interface);
    out.push_str(",\"direction\":");
    out.push_str(match rec.direction {
        Some(Direction::Receive) => "\"R\"",
        Some(Direction::Transmit) => "\"T\"",
        None => "null",
    });
    out.push('}');
}

fn kind_name(kind: FrameKind) -> &'static str {
    match kind {
        FrameKind::Data => "data",
        FrameKind::Remote => "remote",
        FrameKind::Error => "error",
        FrameKind::Fd { .. } => "fd",
    }
}

/// Adds a channel of a Foxglove message type (its schema and encoding) to an MCAP file.
fn add_typed_channel<T: foxglove::Encode, W: Write + Seek>(
    writer: &mut mcap::Writer<W>,
    topic: &str,
) -> anyhow::Result<u16> {
    let (name, encoding, data) = match T::get_schema() {
        Some(s) => (s.name, s.encoding, s.data),
        None => (
            String::new(),
            String::new(),
            std::borrow::Cow::Borrowed(&[][..]),
        ),
    };
    let schema = writer
        .add_schema(&name, &encoding, &data)
        .with_context(|| format!("adding the schema of {topic}"))?;
    writer
        .add_channel(schema, topic, &T::get_message_encoding(), &BTreeMap::new())
        .with_context(|| format!("adding {topic}"))
}

/// The Foxglove view of a trace ([`crate::view`]): the frames replayed through the controller's
/// estimator (the one the live stream reads), with the commands and status the controller sent.
#[derive(Debug)]
struct ViewWriter {
    est: controller::step::estimate::Estimator,
    kin: planner::kinematics::Kinematics,
    track_length_m: f64,
    valves: [Option<f64>; 6],
    status: Option<firmware_bridge::messages::ControllerStatus>,
    tf: u16,
    scene: u16,
    signals: u16,
    log: u16,
    seq: u32,
    scene_written: bool,
    buf: Vec<u8>,
    written: u64,
}

impl ViewWriter {
    fn new<W: Write + Seek>(
        writer: &mut mcap::Writer<W>,
        machine: &planner::machine::MachineConfig,
    ) -> anyhow::Result<Self> {
        use foxglove::messages::{FrameTransforms, Log, SceneUpdate};
        let kin = planner::kinematics::Kinematics::new(machine).context("machine kinematics")?;
        let est = controller::step::estimate::Estimator::new(
            kin.clone(),
            machine.tracks.gauge_m,
            controller::step::estimate::EstimatorConfig::default(),
        )
        .context("state estimator")?;
        Ok(Self {
            est,
            kin,
            track_length_m: machine.tracks.length_m,
            valves: [None; 6],
            status: None,
            tf: add_typed_channel::<FrameTransforms, _>(writer, view::TOPIC_TRANSFORMS)?,
            scene: add_typed_channel::<SceneUpdate, _>(writer, view::TOPIC_SCENE)?,
            signals: add_typed_channel::<view::Signals, _>(writer, view::TOPIC_SIGNALS)?,
            log: add_typed_channel::<Log, _>(writer, view::TOPIC_LOG)?,
            seq: 0,
            scene_written: false,
            buf: Vec::with_capacity(1024),
            written: 0,
        })
    }

    fn write<T: foxglove::Encode, W: Write + Seek>(
        &mut self,
        writer: &mut mcap::Writer<W>,
        channel_id: u16,
        t_ns: u64,
        msg: &T,
    ) -> anyhow::Result<()> {
        self.buf.clear();
        msg.encode(&mut self.buf)
            .map_err(|e| anyhow::anyhow!("encoding a view message: {e}"))?;
        writer
            .write_to_known_channel(
                &mcap::records::MessageHeader {
                    channel_id,
                    sequence: self.seq,
                    log_time: t_ns,
                    publish_time: t_ns,
                },
                &self.buf,
            )
            .context("writing a view message")?;
        self.seq = self.seq.wrapping_add(1);
        self.written += 1;
        Ok(())
    }

    /// One record: the estimator takes the gateway's frames; each joint-angle frame (the resolvers'
    /// 100 Hz) writes the frames and the signals; a change of activity or fault writes a log line.
    fn record<W: Write + Seek>(
        &mut self,
        writer: &mut mcap::Writer<W>,
        rec: &TraceRecord,
    ) -> anyhow::Result<()> {
        use firmware_bridge::messages::{Activity, Valve};
        let Ok(decoded) = Message::decode(&rec.frame) else {
            return Ok(());
        };
        let t = rec.timestamp_ns;
        let sa = decoded.id.source_address();
        match decoded.message {
            Message::AuxValveCommand(c) if sa == firmware_bridge::CONTROLLER_ADDRESS => {
                let i = match c.valve {
                    Valve::Boom => 0,
                    Valve::Stick => 1,
                    Valve::Bucket => 2,
                    Valve::Swing => 3,
                    Valve::LeftTrack => 4,
                    Valve::RightTrack => 5,
                };
                self.valves[i] = Some(c.to_fraction());
            }
            Message::ControllerStatus(s) if sa == firmware_bridge::CONTROLLER_ADDRESS => {
                let before = self.status.replace(s);
                let changed = before
                    .is_none_or(|b| b.activity != s.activity || b.fault_reason != s.fault_reason);
                if changed {
                    let level = if s.activity == Activity::Faulted {
                        foxglove::messages::log::Level::Error
                    } else {
                        foxglove::messages::log::Level::Info
                    };
                    let text = format!(
                        "{:?} (dig {}, stage {:?}, fault code {})",
                        s.activity, s.dig_index, s.stage, s.fault_reason
                    );
                    self.write(writer, self.log, t, &view::log(t, level, text))?;
                }
            }
            m if sa == firmware_bridge::GATEWAY_ADDRESS => {
                self.est.on_message(&m, t as f64 * 1e-9);
                if let Message::JointAngles(_) = m {
                    self.est.update();
                    self.write_state(writer, t)?;
                }
            }
            _ => {}
        }
        Ok(())
    }

    fn write_state<W: Write + Seek>(
        &mut self,
        writer: &mut mcap::Writer<W>,
        t: u64,
    ) -> anyhow::Result<()> {
        let st = *self.est.state();
        if !self.scene_written {
            let scene = view::scene(view::machine_entities(&self.kin, self.track_length_m, t));
            self.write(writer, self.scene, t, &scene)?;
            self.scene_written = true;
        }
        let tf = view::machine_transforms(&self.kin, &st.joints, st.swing_rad, &st.pose, t);
        self.write(writer, self.tf, t, &tf)?;
        let mut signals = view::estimate_signals(&view::EstimateSample::of(&st));
        signals.valve_command = view::ValveCommands::from_array(self.valves);
        if let Some(s) = &self.status {
            view::apply_status(&mut signals, s);
        }
        self.write(writer, self.signals, t, &signals)
    }
}

/// Writes `input` as MCAP to `out`: the decoded `/can/...` channels and `/can/raw` (JSON), and the
/// The MCAP writer's options: zstd-compressed chunks of [`MCAP_CHUNK_BYTES`] with a message index
/// after each chunk and chunk indexes in the summary, so that a reader seeks by time and topic
/// without decompressing every chunk.
fn mcap_options() -> mcap::WriteOptions {
    mcap::WriteOptions::new()
        .compression(Some(mcap::Compression::Zstd))
        .compression_level(MCAP_ZSTD_LEVEL)
        .chunk_size(Some(MCAP_CHUNK_BYTES))
        .emit_message_indexes(true)
        .emit_chunk_indexes(true)
        .emit_statistics(true)
        .emit_summary_offsets(true)
}

/// Uncompressed bytes per MCAP chunk: larger chunks compress the JSON messages better, and the
/// message index still finds a message within its chunk.
pub const MCAP_CHUNK_BYTES: u64 = 4 * 1024 * 1024;

/// The zstd level of MCAP chunks.
pub const MCAP_ZSTD_LEVEL: u32 = 9;

/// Foxglove view of the session ([`crate::view`]) for `machine`, in zstd-compressed chunks.
///
/// # Errors
/// Read errors (as [`input::for_each_record`]), a machine whose kinematics cannot be built, and
/// MCAP write errors.
pub fn to_mcap<R: BufRead, W: Write + Seek>(
    input: R,
    out: W,
    machine: &planner::machine::MachineConfig,
    read: impl Into<input::ReadOptions>,
    diag: &mut dyn Write,
) -> anyhow::Result<ConvertSummary> {
    let mut writer = mcap_options()
        .profile("")
        .library(concat!("excavator-ctl ", env!("CARGO_PKG_VERSION")))
        .create(out)
        .context("starting the MCAP file")?;
    let raw_schema = writer
        .add_schema("CanFrame", "jsonschema", RAW_SCHEMA.as_bytes())
        .context("adding the raw frame schema")?;
    let raw_channel = writer
        .add_channel(raw_schema, "/can/raw", "json", &BTreeMap::new())
        .context("adding /can/raw")?;
    let mut view = ViewWriter::new(&mut writer, machine)?;
    let mut schemas: HashMap<usize, u16> = HashMap::new();
    // (message index, source address) -> (channel id, sequence)
    let mut channels: HashMap<(usize, u8), (u16, u32)> = HashMap::new();
    let mut raw_seq = 0u32;
    let mut payload = String::with_capacity(512);
    let mut written = 0u64;
    let read = input::for_each_record(input, read, diag, |rec| {
        let t = rec.timestamp_ns;
        view.record(&mut writer, &rec)?;
        let Some((msg_index, desc)) = signals::message_of(&rec.frame) else {
            // Frames outside the protocol (unknown ids, error frames) keep their bytes here.
            raw_json(&rec, &mut payload);
            writer
                .write_to_known_channel(
                    &mcap::records::MessageHeader {
                        channel_id: raw_channel,
                        sequence: raw_seq,
                        log_time: t,
                        publish_time: t,
                    },
                    payload.as_bytes(),
                )
                .context("writing /can/raw")?;
            raw_seq = raw_seq.wrapping_add(1);
            return Ok(true);
        };
        let sa = (rec.frame.id().raw() & 0xFF) as u8;
        let key = (msg_index, sa);
        if let std::collections::hash_map::Entry::Vacant(slot) = channels.entry(key) {
            let schema = match schemas.get(&msg_index) {
                Some(s) => *s,
                None => {
                    let s = writer
                        .add_schema(desc.name, "jsonschema", json_schema(desc).as_bytes())
                        .context("adding a schema")?;
                    schemas.insert(msg_index, s);
                    s
                }
            };
            let default_sa = J1939Id::from_raw(desc.default_id)
                .map(|j| j.source_address())
                .unwrap_or(sa);
            let topic = if sa == default_sa {
                format!("/can/{}", desc.name)
            } else {
                format!("/can/{}/sa_{sa:02X}", desc.name)
            };
            let mut meta = BTreeMap::new();
            meta.insert("pgn".to_string(), format!("{:#06X}", desc.pgn));
            meta.insert("source_address".to_string(), format!("{sa:#04X}"));
            let ch = writer
                .add_channel(schema, &topic, "json", &meta)
                .with_context(|| format!("adding {topic}"))?;
            slot.insert((ch, 0));
        }
        if let Some((ch, seq)) = channels.get_mut(&key) {
            message_json(desc, &rec.frame, &mut payload);
            writer
                .write_to_known_channel(
                    &mcap::records::MessageHeader {
                        channel_id: *ch,
                        sequence: *seq,
                        log_time: t,
                        publish_time: t,
                    },
                    payload.as_bytes(),
                )
                .context("writing an MCAP message")?;
            *seq = seq.wrapping_add(1);
            written += 1;
        }
        Ok(true)
    })?;
    writer.finish().context("finishing the MCAP file")?;
    Ok(ConvertSummary {
        read,
        written,
        view_written: view.written,
    })
}

/// Runs `trace convert`.
///
/// # Errors
/// As [`to_csv`] / [`to_mcap`], and an output file that cannot be created.
pub fn run(args: &ConvertArgs) -> anyhow::Result<()> {
    let read = args.input.read_options()?;
    let reader = input::open(&args.input.file)?;
    let file =
        File::create(&args.out).with_context(|| format!("cannot create {}", args.out.display()))?;
    let mut diag = io::stderr();
    let summary = match args.format {
        Format::Csv => {
            let mut out = BufWriter::with_capacity(256 * 1024, file);
            to_csv(
                reader,
                &mut out,
                args.rows,
                args.step_ms * 1e-3,
                &args.signals,
                read,
                &mut diag,
            )
            .with_context(|| format!("converting {}", args.input.file.display()))?
        }
        Format::Mcap => {
            let machine = planner::machine::MachineConfig::load_or_default(args.machine.as_deref())
                .context("machine file")?;
            to_mcap(
                reader,
                BufWriter::with_capacity(256 * 1024, file),
                &machine,
                read,
                &mut diag,
            )
            .with_context(|| format!("converting {}", args.input.file.display()))?
        }
    };
    let view = match args.format {
        Format::Csv => String::new(),
        Format::Mcap => format!(", {} view message(s)", summary.view_written),
    };
    eprintln!(
        "{}: {} record(s) read, {} {} written{view}",
        args.out.display(),
        summary.read.records,
        summary.written,
        match args.format {
            Format::Csv => "row(s)",
            Format::Mcap => "decoded message(s)",
        }
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const TEXT: &str = "\
(1700000000.000000) vcan0 0CFF5080#7C14C8FB7EB2B57A
(1700000000.004000) vcan0 0CFE3027#7DFF31204EFFFFFF
(1700000000.010000) vcan0 0CFF5080#0000000000000000
";

    #[test]
    fn csv_rows_per_frame_forward_fill() {
        let mut out = Vec::new();
        let names = [
            "BoomAngle".to_string(),
            "AuxValveCommand_Boom.PortFlowCommandFine".to_string(),
        ];
        to_csv(
            TEXT.as_bytes(),
            &mut out,
            Rows::Frame,
            0.01,
            &names,
            false,
            &mut io::sink(),
        )
        .unwrap();
        let text = String::from_utf8(out).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(
            lines[0],
            "timestamp_s,t_s,JointAngles.BoomAngle,AuxValveCommand_Boom.PortFlowCommandFine"
        );
        assert_eq!(lines[1], "1700000000.000000,0.000000000,0.5244,");
        assert_eq!(lines[2], "1700000000.004000,0.004000000,0.5244,50");
        assert_eq!(lines[3], "1700000000.010000,0.010000000,0,50");
    }

    #[test]
    fn csv_rows_per_step_hold_values() {
        let mut out = Vec::new();
        to_csv(
            TEXT.as_bytes(),
            &mut out,
            Rows::Step,
            0.005,
            &["BoomAngle".to_string()],
            false,
            &mut io::sink(),
        )
        .unwrap();
        let text = String::from_utf8(out).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        // Rows at 0 and 5 ms hold the first frame's value, the final row at 10 ms the last one.
        assert_eq!(lines.len(), 4, "{text}");
        assert!(lines[1].ends_with(",0.5244"), "{text}");
        assert!(lines[2].ends_with(",0.5244"), "{text}");
        assert!(lines[3].ends_with(",0"), "{text}");
    }

    #[test]
    fn schema_describes_every_signal() {
        let schema: serde_json::Value =
            serde_json::from_str(&json_schema(&dbc::aux_valve_command_boom::MESSAGE)).unwrap();
        let props = schema["properties"].as_object().unwrap();
        assert!(props.contains_key("PortFlowCommandFine"));
        assert!(props.contains_key("ValveState_name"));
        assert!(!props.contains_key("PortFlowCommand_name"));
        let mut payload = String::new();
        let frame = CanFrame::new_extended(
            0x0CFE_3027,
            &[0x7D, 0xFF, 0x31, 0x20, 0x4E, 0xFF, 0xFF, 0xFF],
        )
        .unwrap();
        message_json(&dbc::aux_valve_command_boom::MESSAGE, &frame, &mut payload);
        let v: serde_json::Value = serde_json::from_str(&payload).unwrap();
        assert_eq!(v["ValveState_name"], "Extend");
        assert_eq!(v["PortFlowCommandFine"], 50.0);
        assert!(v["error"].is_null());
    }
}
