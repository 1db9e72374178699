//! Signals as the tools show them: every signal of a frame decoded through the DBC descriptors, enum
//! names from the DBC's `VAL_` tables, and `Message.Signal` names.
//!
//! [`firmware_bridge::Message::decode`] is the receiver's view: it rejects a whole frame for one bad
//! signal and reports some values in derived form (the valve command's flow is the fine value). A
//! debugging tool must show what is on the wire, so [`decode_signal`] decodes each signal of the
//! descriptor on its own (as `cantools decode` does) and keeps "not available", "error indicator" and
//! out-of-range raw values visible per signal; the tools add the verdict of `Message::decode` next to
//! it.
//!
//! The generated descriptors carry no value tables, so the `VAL_` lines of the DBC (the single source
//! of truth) are parsed here from the file embedded at build time. They are looked up by signal name:
//! in this DBC a signal name has one meaning wherever it occurs (`ValveState` of every valve command and
//! measurement), while the file only attaches the table to the first message.

use std::collections::HashMap;
use std::sync::OnceLock;

use firmware_bridge::dbc::{self, MessageDesc, SignalDesc};
use firmware_bridge::frame::{CanFrame, CanId, FrameKind};

pub use firmware_bridge::dbc::DBC_TEXT;

/// The decoded value of one signal, as on the wire.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SignalValue {
    /// A physical value within the DBC range.
    Value(f64),
    /// The J1939 "not available" raw value.
    NotAvailable,
    /// The J1939 "error indicator" raw value.
    ErrorIndicator,
    /// Any other raw value outside the DBC range.
    OutOfRange(i64),
}

impl SignalValue {
    /// The physical value, if valid.
    pub fn value(self) -> Option<f64> {
        match self {
            Self::Value(v) => Some(v),
            _ => None,
        }
    }
}

/// Decodes one signal of `data`.
pub fn decode_signal(sig: &SignalDesc, data: &[u8]) -> SignalValue {
    match dbc::decode_raw(sig, data) {
        Ok(raw) => SignalValue::Value(dbc::raw_to_physical(sig, raw)),
        Err(dbc::DecodeError::NotAvailable { .. }) => SignalValue::NotAvailable,
        Err(dbc::DecodeError::ErrorIndicator { .. }) => SignalValue::ErrorIndicator,
        Err(dbc::DecodeError::OutOfRange { raw, .. }) => SignalValue::OutOfRange(raw),
        // decode_raw only returns the three above; keep the raw bits visible anyway.
        Err(_) => SignalValue::OutOfRange(dbc::extract_raw(sig, data).unwrap_or(-1)),
    }
}

/// The raw value of a signal, unchecked (counters); `None` if the data is too short.
pub fn raw_value(sig: &SignalDesc, data: &[u8]) -> Option<i64> {
    dbc::extract_raw(sig, data)
}

/// Index of a message in [`dbc::MESSAGES`].
pub type MessageIndex = usize;

/// Finds the DBC message of a frame: extended data frames whose PGN is in the DBC.
pub fn message_of(frame: &CanFrame) -> Option<(MessageIndex, &'static MessageDesc)> {
    match (frame.kind(), frame.id()) {
        (FrameKind::Data, CanId::Extended(id)) => message_of_id(id),
        _ => None,
    }
}

/// Finds the DBC message of a 29-bit id by its PGN: the one sent from the id's source address where
/// the DBC has one per node (`DM1_Gateway`, `AddressClaimed_Gateway`), else the first of the PGN.
pub fn message_of_id(id: u32) -> Option<(MessageIndex, &'static MessageDesc)> {
    let i = dbc::message_index_by_id(id)?;
    Some((i, dbc::MESSAGES.get(i)?))
}

/// The name of a raw value in the DBC's value table for the signal, if any.
pub fn value_name(signal: &str, raw: i64) -> Option<&'static str> {
    value_tables()
        .by_name
        .get(signal)
        .and_then(|t| t.iter().find(|(v, _)| *v == raw).map(|(_, n)| *n))
}

/// The name of a raw value of `signal` of message `desc` in the DBC's value tables: the message's own
/// table, else the signal name's ([`value_name`]).
pub fn value_name_in(desc: &MessageDesc, signal: &str, raw: i64) -> Option<&'static str> {
    let tables = value_tables();
    tables
        .by_message
        .get(&(dbc_id(desc), signal))
        .or_else(|| tables.by_name.get(signal))
        .and_then(|t| t.iter().find(|(v, _)| *v == raw).map(|(_, n)| *n))
}

/// The DBC value table of signal `sig_index` of message `msg_index`, if it has one (looked up by
/// signal name, see the module docs). Precomputed per signal, so the decode hot path does not hash.
pub fn value_table(
    msg_index: MessageIndex,
    sig_index: usize,
) -> Option<&'static [(i64, &'static str)]> {
    type Table = Option<&'static [(i64, &'static str)]>;
    static PER_SIGNAL: OnceLock<Vec<Vec<Table>>> = OnceLock::new();
    PER_SIGNAL
        .get_or_init(|| {
            let tables = value_tables();
            dbc::MESSAGES
                .iter()
                .map(|m| {
                    m.signals
                        .iter()
                        .map(|s| {
                            tables
                                .by_message
                                .get(&(dbc_id(m), s.name))
                                .or_else(|| tables.by_name.get(s.name))
                                .map(Vec::as_slice)
                        })
                        .collect()
                })
                .collect()
        })
        .get(msg_index)?
        .get(sig_index)
        .copied()
        .flatten()
}

type Table = Vec<(i64, &'static str)>;

/// The `VAL_` tables by message id (as the DBC writes it) and signal, and by signal name (the first).
#[derive(Default)]
struct ValueTables {
    by_message: HashMap<(u32, &'static str), Table>,
    by_name: HashMap<&'static str, Table>,
}

/// A message's id as the DBC writes it (bit 31 set for a 29-bit id).
fn dbc_id(m: &MessageDesc) -> u32 {
    m.default_id | 0x8000_0000
}

fn value_tables() -> &'static ValueTables {
    static TABLES: OnceLock<ValueTables> = OnceLock::new();
    TABLES.get_or_init(|| parse_value_tables(DBC_TEXT))
}

/// Parses `VAL_ <id> <signal> <n> "<name>" ... ;` lines. The first table for a signal name is its
/// table by name.
fn parse_value_tables(text: &'static str) -> ValueTables {
    let mut tables = ValueTables::default();
    for line in text.lines() {
        let Some(rest) = line.trim().strip_prefix("VAL_ ") else {
            continue;
        };
        let mut parts = rest.splitn(3, ' ');
        let (Some(id), Some(signal), Some(body)) = (parts.next(), parts.next(), parts.next())
        else {
            continue;
        };
        let mut entries = Vec::new();
        let mut rest = body.trim();
        while let Some((num, after)) = rest.split_once(" \"") {
            let Some((name, after)) = after.split_once('"') else {
                break;
            };
            if let Ok(v) = num.trim().parse::<i64>() {
                entries.push((v, name));
            }
            rest = after.trim();
        }
        if !entries.is_empty() {
            if let Ok(id) = id.parse::<u32>() {
                tables.by_message.insert((id, signal), entries.clone());
            }
            tables.by_name.entry(signal).or_insert(entries);
        }
    }
    tables
}

/// A signal of a DBC message, addressed as `Message.Signal`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SignalRef {
    /// Index of the message in [`dbc::MESSAGES`].
    pub msg_index: MessageIndex,
    /// Index of the signal in the message's signals.
    pub sig_index: usize,
    /// Its column in [`all_signals`] (the wide CSV's order).
    pub column: usize,
}

impl SignalRef {
    /// The message descriptor.
    pub fn message(&self) -> &'static MessageDesc {
        &dbc::MESSAGES[self.msg_index]
    }

    /// The signal descriptor.
    pub fn signal(&self) -> &'static SignalDesc {
        &dbc::MESSAGES[self.msg_index].signals[self.sig_index]
    }

    /// `Message.Signal`.
    pub fn full_name(&self) -> String {
        format!("{}.{}", self.message().name, self.signal().name)
    }
}

/// Every signal of the DBC, message by message in DBC order; `column` is the position in this list.
pub fn all_signals() -> &'static [SignalRef] {
    static ALL: OnceLock<Vec<SignalRef>> = OnceLock::new();
    ALL.get_or_init(|| {
        let mut out = Vec::new();
        for (msg_index, m) in dbc::MESSAGES.iter().enumerate() {
            for sig_index in 0..m.signals.len() {
                let column = out.len();
                out.push(SignalRef {
                    msg_index,
                    sig_index,
                    column,
                });
            }
        }
        out
    })
}

/// Column of the first signal of each message in [`all_signals`].
pub fn first_column(msg_index: MessageIndex) -> usize {
    dbc::MESSAGES[..msg_index.min(dbc::MESSAGES.len())]
        .iter()
        .map(|m| m.signals.len())
        .sum()
}

/// Resolves a signal name: `Message.Signal` (exact), or a bare `Signal` that names exactly one signal
/// of the DBC. Names are case-insensitive.
///
/// # Errors
/// Unknown names, and bare names shared by several messages (listing the candidates).
pub fn resolve_signal(name: &str) -> Result<SignalRef, String> {
    let all = all_signals();
    let matches: Vec<&SignalRef> = if let Some((msg, sig)) = name.split_once('.') {
        all.iter()
            .filter(|s| {
                s.message().name.eq_ignore_ascii_case(msg)
                    && s.signal().name.eq_ignore_ascii_case(sig)
            })
            .collect()
    } else {
        all.iter()
            .filter(|s| s.signal().name.eq_ignore_ascii_case(name))
            .collect()
    };
    match matches.as_slice() {
        [one] => Ok(**one),
        [] => Err(format!(
            "unknown signal {name:?} (use Message.Signal, e.g. JointAngles.BoomAngle)"
        )),
        many => Err(format!(
            "signal {name:?} is in several messages; say which: {}",
            many.iter()
                .map(|s| s.full_name())
                .collect::<Vec<_>>()
                .join(", ")
        )),
    }
}

/// Resolves a message name: exact DBC name (`AuxValveCommand_Boom`), or the family before the `_`
/// (`AuxValveCommand` selects all six). Case-insensitive.
///
/// # Errors
/// No message matches.
pub fn resolve_messages(name: &str) -> Result<Vec<MessageIndex>, String> {
    let found: Vec<MessageIndex> = dbc::MESSAGES
        .iter()
        .enumerate()
        .filter(|(_, m)| {
            m.name.eq_ignore_ascii_case(name)
                || m.name
                    .split_once('_')
                    .is_some_and(|(family, _)| family.eq_ignore_ascii_case(name))
        })
        .map(|(i, _)| i)
        .collect();
    if found.is_empty() {
        let names: Vec<&str> = dbc::MESSAGES.iter().map(|m| m.name).collect();
        return Err(format!(
            "unknown message {name:?}; known: {}",
            names.join(", ")
        ));
    }
    Ok(found)
}

/// The nominal period of a message from `busload::SCHEDULE`, seconds.
pub fn nominal_period_s(msg: &MessageDesc) -> Option<f64> {
    firmware_bridge::busload::SCHEDULE
        .iter()
        .find(|e| e.message == msg.name && e.rate_hz > 0.0)
        .map(|e| 1.0 / e.rate_hz)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn value_tables_come_from_the_dbc() {
        assert_eq!(value_name("ValveState", 1), Some("Extend"));
        assert_eq!(value_name("ValveState", 15), Some("NotAvailable"));
        assert_eq!(value_name("AutodigStage", 2), Some("PreDig"));
        assert_eq!(value_name("Activity", 9), Some("Faulted"));
        assert_eq!(value_name("RequestedMode", 3), Some("EStop"));
        assert_eq!(value_name("BoomAngle", 0), None);
        // The stick command has no VAL_ line of its own; the boom's table applies by name.
        let (stick, _) = message_of_id(0x0CFE_3127).unwrap();
        let table = value_table(stick, 2).unwrap();
        assert!(table.contains(&(2, "Retract")));
        assert!(value_table(stick, 0).is_none());
    }

    #[test]
    fn names_resolve_or_explain() {
        let s = resolve_signal("BoomAngle").unwrap();
        assert_eq!(s.full_name(), "JointAngles.BoomAngle");
        assert_eq!(
            resolve_signal("auxvalvemeasured_boom.extendportpressure")
                .unwrap()
                .full_name(),
            "AuxValveMeasured_Boom.ExtendPortPressure"
        );
        let err = resolve_signal("ValveState").unwrap_err();
        assert!(err.contains("AuxValveMeasured_Stick.ValveState"), "{err}");
        assert!(resolve_signal("Nope").is_err());
        assert_eq!(resolve_messages("AuxValveCommand").unwrap().len(), 6);
        assert_eq!(resolve_messages("jointangles").unwrap().len(), 1);
        assert!(resolve_messages("Foo").is_err());
    }

    #[test]
    fn columns_are_consistent() {
        for s in all_signals() {
            assert_eq!(first_column(s.msg_index) + s.sig_index, s.column);
        }
    }

    #[test]
    fn special_values_stay_visible() {
        // Boom angle not available (0x7FFF), stick error indicator (0x7FFE), bucket 0.512 rad.
        let data = [0xFF, 0x7F, 0xFE, 0x7F, 0x00, 0x14, 0x00, 0x00];
        let sigs = dbc::joint_angles::SIGNALS;
        assert_eq!(decode_signal(&sigs[0], &data), SignalValue::NotAvailable);
        assert_eq!(decode_signal(&sigs[1], &data), SignalValue::ErrorIndicator);
        assert_eq!(decode_signal(&sigs[2], &data), SignalValue::Value(0.512));
    }
}
