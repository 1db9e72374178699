//! A DBC loaded at run time and the generic signal codec for it: what a machine profile
//! ([`crate::profile`]) uses to speak another gateway's messages.
//!
//! The compiled protocol ([`crate::dbc`], generated from `excavator.dbc` at build time) only needs
//! what the project's own DBC contains. A gateway's DBC can contain more, and this codec handles it:
//!
//! - Intel (`@1`, little-endian) and Motorola (`@0`, big-endian, the DBC "sawtooth" bit numbering
//!   where the start bit is the signal's most significant bit) byte order;
//! - unsigned and two's-complement signed integers of 1 to 64 bits, and IEEE floats
//!   (`SIG_VALTYPE_ ... : 1` for 32 bits, `: 2` for 64 bits), with factor and offset applied as
//!   `physical = raw * factor + offset` for all of them (as `cantools` does);
//! - 11-bit and 29-bit ids;
//! - simple multiplexing: one multiplexor switch (`M`) per message and signals present for one switch
//!   value (`m3`); extended multiplexing (`SG_MUL_VAL_`, `m3M`) is refused at load;
//! - value tables (`VAL_`): a raw value's name and the raw value of a name.
//!
//! Loading ([`WireDbc::parse`]) checks every signal fits its message and every multiplexed signal has
//! a multiplexor, so decoding and encoding afterwards cannot index out of the payload. Decoding never
//! panics on any payload; encoding refuses values that do not fit the signal instead of clamping.

use can_dbc::{
    AttributeValue, ByteOrder as DbcByteOrder, Dbc, MessageId, MultiplexIndicator, NumericValue,
    SignalExtendedValueType, ValueDescription, ValueType,
};

use crate::frame::{CAN_MAX_LEN, CanFrame, CanId, FrameKind};

/// Why a DBC could not be loaded.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LoadError {
    /// The text is not a DBC (the parser's message names the line and column).
    #[error("not a valid DBC: {0}")]
    Parse(String),
    /// A message or signal uses something the codec does not support, or does not fit.
    #[error("message {message}: {reason}")]
    Unsupported {
        /// The message name.
        message: String,
        /// What is wrong, naming the signal.
        reason: String,
    },
}

/// Why a payload could not be decoded.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DecodeError {
    /// The payload length differs from the message's.
    #[error("{message}: {actual} data bytes, expected {expected}")]
    WrongLength {
        /// The message name.
        message: String,
        /// Bytes in the message definition.
        expected: usize,
        /// Bytes received.
        actual: usize,
    },
    /// The multiplexor holds a value no signal of the message is defined for.
    #[error("{message}: multiplexor value {value} selects no signals")]
    UnknownMux {
        /// The message name.
        message: String,
        /// The multiplexor's raw value.
        value: u64,
    },
}

/// Why a value could not be encoded. No value is clamped.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EncodeError {
    /// NaN or infinite.
    #[error("signal {signal}: value is not finite")]
    NotFinite {
        /// The signal name.
        signal: String,
    },
    /// The value does not fit the signal's bits, or lies outside its `[min, max]`.
    #[error("signal {signal}: value {value} does not fit (range [{min}, {max}])")]
    OutOfRange {
        /// The signal name.
        signal: String,
        /// The rejected value.
        value: f64,
        /// Smallest valid value.
        min: f64,
        /// Largest valid value.
        max: f64,
    },
    /// No signal of this name in the message.
    #[error("{message} has no signal {signal}")]
    UnknownSignal {
        /// The message name.
        message: String,
        /// The name asked for.
        signal: String,
    },
    /// A multiplexed signal given for another multiplexor value than the frame's.
    #[error("signal {signal} belongs to multiplexor value {signal_mux}, the frame has {frame_mux}")]
    MuxMismatch {
        /// The signal name.
        signal: String,
        /// The value the signal is defined for.
        signal_mux: u64,
        /// The value of the frame's multiplexor.
        frame_mux: u64,
    },
}

/// Byte order of a signal.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ByteOrder {
    /// Little-endian, `@1`: the start bit is the least significant bit.
    Intel,
    /// Big-endian, `@0`: the start bit is the most significant bit, in the DBC's sawtooth numbering.
    Motorola,
}

/// How a signal's raw bits are read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ValueKind {
    /// Unsigned integer.
    Unsigned,
    /// Two's-complement signed integer.
    Signed,
    /// IEEE 754 single precision (32 bits).
    Float32,
    /// IEEE 754 double precision (64 bits).
    Float64,
}

/// A signal's place in a multiplexed message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mux {
    /// Always present.
    Plain,
    /// The multiplexor switch.
    Multiplexor,
    /// Present when the switch holds this value.
    Multiplexed(u64),
}

/// One signal of a loaded DBC.
#[derive(Debug, Clone, PartialEq)]
pub struct WireSignal {
    /// Signal name.
    pub name: String,
    /// Start bit as written in the DBC.
    pub start_bit: u16,
    /// Length in bits.
    pub len: u16,
    /// Byte order.
    pub byte_order: ByteOrder,
    /// Integer or float.
    pub kind: ValueKind,
    /// Physical value per raw unit.
    pub factor: f64,
    /// Physical offset.
    pub offset: f64,
    /// Smallest valid physical value (with `max`, both 0 means "no limit", as in `cantools`).
    pub min: f64,
    /// Largest valid physical value.
    pub max: f64,
    /// Unit string.
    pub unit: String,
    /// Multiplexing.
    pub mux: Mux,
    /// Named raw values (`VAL_`), in DBC order.
    pub value_table: Vec<(i64, String)>,
    /// Payload bit positions (`byte * 8 + bit`, bit 0 = least significant bit of the byte) from the
    /// raw value's least significant bit up.
    positions: Vec<u16>,
}

/// One message of a loaded DBC.
#[derive(Debug, Clone, PartialEq)]
pub struct WireMessage {
    /// Message name.
    pub name: String,
    /// The CAN id (11 or 29 bits).
    pub id: CanId,
    /// Payload length in bytes.
    pub size: usize,
    /// Sending node, empty if the DBC names none.
    pub transmitter: String,
    /// Signals in DBC order.
    pub signals: Vec<WireSignal>,
    /// Index of the multiplexor switch in `signals`, if the message is multiplexed.
    pub multiplexor: Option<usize>,
    /// The message's `GenMsgCycleTime` attribute, ms: its transmit period (each multiplexor value's,
    /// for a multiplexed message); `None` when the DBC gives none or 0 (not periodic).
    pub cycle_time_ms: Option<u32>,
}

/// A DBC loaded at run time.
#[derive(Debug, Clone, PartialEq)]
pub struct WireDbc {
    /// Messages in DBC order.
    pub messages: Vec<WireMessage>,
    /// Whether the DBC describes a J1939 network (database attribute `ProtocolType` `J1939`).
    pub j1939: bool,
}

fn num(v: &NumericValue) -> f64 {
    match *v {
        NumericValue::Uint(u) => u as f64,
        NumericValue::Int(i) => i as f64,
        NumericValue::Double(d) => d,
    }
}

/// The payload bit positions of a signal from its least significant bit up, or `None` if it leaves
/// a payload of `size` bytes.
fn bit_positions(start_bit: u64, len: u64, order: ByteOrder, size: usize) -> Option<Vec<u16>> {
    let total = (size * 8) as u64;
    let mut out = Vec::with_capacity(len as usize);
    match order {
        ByteOrder::Intel => {
            for i in 0..len {
                let pos = start_bit.checked_add(i)?;
                out.push(u16::try_from(pos).ok().filter(|&p| u64::from(p) < total)?);
            }
        }
        ByteOrder::Motorola => {
            // Most significant bit first, moving toward bit 0 of a byte, then to bit 7 of the next.
            let mut pos = start_bit;
            for i in 0..len {
                out.push(u16::try_from(pos).ok().filter(|&p| u64::from(p) < total)?);
                if i + 1 < len {
                    pos = if pos.is_multiple_of(8) {
                        pos + 15
                    } else {
                        pos - 1
                    };
                }
            }
            out.reverse();
        }
    }
    Some(out)
}

/// The 1-based line of message `name`'s `BO_` definition in DBC `text`.
fn message_line(text: &str, name: &str) -> Option<usize> {
    let needle = format!(" {name}:");
    text.lines()
        .position(|l| l.trim_start().starts_with("BO_ ") && l.contains(&needle))
        .map(|i| i + 1)
}

impl WireDbc {
    /// Parses DBC text.
    ///
    /// # Errors
    /// [`LoadError::Parse`] for text that is not a DBC, [`LoadError::Unsupported`] for a signal that
    /// leaves its message, has a length the codec cannot hold (0, above 64, a float that is not 32 or
    /// 64 bits), a multiplexed signal without a multiplexor, extended multiplexing, a message longer
    /// than 8 bytes, or two messages with one CAN id (naming the second one's line).
    pub fn parse(text: &str) -> Result<Self, LoadError> {
        let dbc = Dbc::try_from(text).map_err(|e| LoadError::Parse(e.to_string()))?;
        let mut messages = Vec::with_capacity(dbc.messages.len());
        for msg in &dbc.messages {
            let m = load_message(&dbc, msg)?;
            // One id, one meaning: a second message on an id would decode its frames as either.
            if let Some(other) = messages.iter().find(|o: &&WireMessage| o.id == m.id) {
                let line =
                    message_line(text, &m.name).map_or(String::new(), |l| format!("line {l}: "));
                return Err(LoadError::Unsupported {
                    reason: format!(
                        "{line}CAN id {} is already message {}'s: an id must name one message",
                        m.id, other.name
                    ),
                    message: m.name,
                });
            }
            messages.push(m);
        }
        let j1939 = dbc.attribute_values_database.iter().any(|a| {
            a.name == "ProtocolType"
                && matches!(&a.value, can_dbc::AttributeValue::String(v) if v == "J1939")
        });
        Ok(Self { messages, j1939 })
    }

    /// The message with this name.
    pub fn message(&self, name: &str) -> Option<&WireMessage> {
        self.messages.iter().find(|m| m.name == name)
    }

    /// The index of the message with this id.
    pub fn message_index_by_id(&self, id: CanId) -> Option<usize> {
        self.messages.iter().position(|m| m.id == id)
    }
}

fn load_message(dbc: &Dbc, msg: &can_dbc::Message) -> Result<WireMessage, LoadError> {
    let unsupported = |reason: String| LoadError::Unsupported {
        message: msg.name.clone(),
        reason,
    };
    let id = match msg.id {
        MessageId::Standard(raw) => CanId::standard(raw),
        MessageId::Extended(raw) => CanId::extended(raw),
    }
    .map_err(|e| unsupported(e.to_string()))?;
    let size = usize::try_from(msg.size)
        .ok()
        .filter(|&s| s <= CAN_MAX_LEN)
        .ok_or_else(|| {
            unsupported(format!(
                "{} bytes (classic CAN carries at most 8)",
                msg.size
            ))
        })?;
    if dbc
        .extended_multiplex
        .iter()
        .any(|m| m.message_id == msg.id)
    {
        return Err(unsupported(
            "extended multiplexing (SG_MUL_VAL_) is not supported".into(),
        ));
    }
    let mut signals = Vec::with_capacity(msg.signals.len());
    let mut multiplexor = None;
    for sig in &msg.signals {
        let byte_order = match sig.byte_order {
            DbcByteOrder::LittleEndian => ByteOrder::Intel,
            DbcByteOrder::BigEndian => ByteOrder::Motorola,
        };
        let kind = match dbc.extended_value_type_for_signal(msg.id, &sig.name) {
            Some(SignalExtendedValueType::IEEEfloat32Bit) => ValueKind::Float32,
            Some(SignalExtendedValueType::IEEEdouble64bit) => ValueKind::Float64,
            _ => match sig.value_type {
                ValueType::Signed => ValueKind::Signed,
                ValueType::Unsigned => ValueKind::Unsigned,
            },
        };
        let len_ok = match kind {
            ValueKind::Float32 => sig.size == 32,
            ValueKind::Float64 => sig.size == 64,
            _ => (1..=64).contains(&sig.size),
        };
        if !len_ok {
            return Err(unsupported(format!(
                "signal {}: {} bits is not a valid length for {kind:?}",
                sig.name, sig.size
            )));
        }
        let positions =
            bit_positions(sig.start_bit, sig.size, byte_order, size).ok_or_else(|| {
                unsupported(format!(
                    "signal {} (start bit {}, {} bits, {byte_order:?}) does not fit {size} bytes",
                    sig.name, sig.start_bit, sig.size
                ))
            })?;
        if !(sig.factor.is_finite() && sig.factor != 0.0 && sig.offset.is_finite()) {
            return Err(unsupported(format!(
                "signal {}: factor {} and offset {} must be finite, factor non-zero",
                sig.name, sig.factor, sig.offset
            )));
        }
        let mux = match sig.multiplexer_indicator {
            MultiplexIndicator::Plain => Mux::Plain,
            MultiplexIndicator::Multiplexor => {
                if !matches!(kind, ValueKind::Unsigned) {
                    return Err(unsupported(format!(
                        "multiplexor {} must be an unsigned integer",
                        sig.name
                    )));
                }
                multiplexor = Some(signals.len());
                Mux::Multiplexor
            }
            MultiplexIndicator::MultiplexedSignal(v) => Mux::Multiplexed(v),
            MultiplexIndicator::MultiplexorAndMultiplexedSignal(_) => {
                return Err(unsupported(format!(
                    "signal {}: nested multiplexing (m..M) is not supported",
                    sig.name
                )));
            }
        };
        let value_table = dbc
            .value_descriptions
            .iter()
            .find_map(|d| match d {
                ValueDescription::Signal {
                    message_id,
                    name,
                    value_descriptions,
                } if *message_id == msg.id && *name == sig.name => Some(
                    value_descriptions
                        .iter()
                        .map(|v| (v.id, v.description.clone()))
                        .collect(),
                ),
                _ => None,
            })
            .unwrap_or_default();
        signals.push(WireSignal {
            name: sig.name.clone(),
            start_bit: u16::try_from(sig.start_bit).unwrap_or(u16::MAX),
            len: sig.size as u16, // 1..=64, checked above
            byte_order,
            kind,
            factor: sig.factor,
            offset: sig.offset,
            min: num(&sig.min),
            max: num(&sig.max),
            unit: sig.unit.clone(),
            mux,
            value_table,
            positions,
        });
    }
    if multiplexor.is_none()
        && let Some(s) = signals
            .iter()
            .find(|s| matches!(s.mux, Mux::Multiplexed(_)))
    {
        return Err(unsupported(format!(
            "signal {} is multiplexed but the message has no multiplexor (M)",
            s.name
        )));
    }
    let cycle_time_ms = match dbc
        .attribute_values_message
        .iter()
        .find(|a| a.name == "GenMsgCycleTime" && a.message_id == msg.id)
        .map(|a| &a.value)
    {
        None => None,
        Some(AttributeValue::Uint(v)) => Some(i128::from(*v)),
        Some(AttributeValue::Int(v)) => Some(i128::from(*v)),
        Some(other) => {
            return Err(unsupported(format!(
                "GenMsgCycleTime {other:?} is not a whole number of ms"
            )));
        }
    };
    let cycle_time_ms = match cycle_time_ms.map(u32::try_from) {
        None | Some(Ok(0)) => None,
        Some(Ok(ms)) => Some(ms),
        Some(Err(_)) => {
            return Err(unsupported(format!(
                "GenMsgCycleTime {} is not a whole number of ms up to {}",
                cycle_time_ms.unwrap_or_default(),
                u32::MAX
            )));
        }
    };
    Ok(WireMessage {
        name: msg.name.clone(),
        id,
        size,
        transmitter: msg.transmitter.clone().unwrap_or_default(),
        signals,
        multiplexor,
        cycle_time_ms,
    })
}

impl WireSignal {
    /// The raw bits of the signal in `data` (the low `len` bits of the result). `data` must be at least
    /// as long as the signal's message; shorter data reads missing bits as 0.
    pub fn bits(&self, data: &[u8]) -> u64 {
        let mut raw = 0u64;
        for (i, &pos) in self.positions.iter().enumerate() {
            let byte = data.get(usize::from(pos / 8)).copied().unwrap_or(0);
            if byte >> (pos % 8) & 1 == 1 {
                raw |= 1 << i;
            }
        }
        raw
    }

    /// Writes the low `len` bits of `raw` into `data` at the signal's place.
    pub fn put_bits(&self, raw: u64, data: &mut [u8]) {
        for (i, &pos) in self.positions.iter().enumerate() {
            if let Some(byte) = data.get_mut(usize::from(pos / 8)) {
                let mask = 1u8 << (pos % 8);
                if raw >> i & 1 == 1 {
                    *byte |= mask;
                } else {
                    *byte &= !mask;
                }
            }
        }
    }

    /// The raw bits as an integer value: sign-extended for a signed signal.
    pub fn raw_integer(&self, bits: u64) -> i128 {
        match self.kind {
            ValueKind::Signed if self.len < 64 => {
                let shift = 64 - u32::from(self.len);
                i128::from(((bits << shift) as i64) >> shift)
            }
            ValueKind::Signed => i128::from(bits as i64),
            _ => i128::from(bits),
        }
    }

    /// The physical value of raw bits: `raw * factor + offset`, the raw being an integer or a float.
    pub fn physical(&self, bits: u64) -> f64 {
        let raw = match self.kind {
            ValueKind::Float32 => f64::from(f32::from_bits(bits as u32)),
            ValueKind::Float64 => f64::from_bits(bits),
            _ => self.raw_integer(bits) as f64,
        };
        raw * self.factor + self.offset
    }

    /// The smallest and largest raw integer the signal's bits hold (for floats, the full bits).
    pub fn raw_limits(&self) -> (i128, i128) {
        let len = u32::from(self.len);
        match self.kind {
            ValueKind::Signed => (-(1i128 << (len - 1)), (1i128 << (len - 1)) - 1),
            _ => (0, (1i128 << len) - 1),
        }
    }

    /// True if `[min, max]` limits the value (`cantools` reads `[0|0]` as no limit).
    pub fn has_limits(&self) -> bool {
        !(self.min == 0.0 && self.max == 0.0)
    }

    /// The raw bits of a physical value, the integer raw rounded to nearest.
    ///
    /// # Errors
    /// [`EncodeError::NotFinite`] for NaN or infinity; [`EncodeError::OutOfRange`] if the raw value
    /// does not fit the bits, or (with `check_limits`) the value lies outside `[min, max]`.
    pub fn bits_of(&self, value: f64, check_limits: bool) -> Result<u64, EncodeError> {
        if !value.is_finite() {
            return Err(EncodeError::NotFinite {
                signal: self.name.clone(),
            });
        }
        let out_of_range = || EncodeError::OutOfRange {
            signal: self.name.clone(),
            value,
            min: self.min,
            max: self.max,
        };
        if check_limits && self.has_limits() {
            // Half a raw step of slack: a limit written with fewer decimals than the grid.
            let slack =
                (self.factor.abs() * 0.5).min(1e-9 * (1.0 + self.max.abs().max(self.min.abs())));
            if value < self.min - slack || value > self.max + slack {
                return Err(out_of_range());
            }
        }
        let raw = (value - self.offset) / self.factor;
        match self.kind {
            ValueKind::Float32 => {
                let f = raw as f32;
                if !f.is_finite() {
                    return Err(out_of_range());
                }
                Ok(u64::from(f.to_bits()))
            }
            ValueKind::Float64 => Ok(raw.to_bits()),
            _ => {
                let rounded = raw.round();
                let (lo, hi) = self.raw_limits();
                if rounded < lo as f64 || rounded > hi as f64 {
                    return Err(out_of_range());
                }
                let int = rounded as i128;
                Ok(self.bits_of_integer(int))
            }
        }
    }

    /// The bits of a raw integer (two's complement truncated to `len` bits for a signed signal).
    pub fn bits_of_integer(&self, raw: i128) -> u64 {
        let mask = if self.len >= 64 {
            u64::MAX
        } else {
            (1u64 << self.len) - 1
        };
        (raw as u64) & mask
    }

    /// The name of a raw value in the signal's value table.
    pub fn value_name(&self, raw: i128) -> Option<&str> {
        self.value_table
            .iter()
            .find(|(v, _)| i128::from(*v) == raw)
            .map(|(_, name)| name.as_str())
    }

    /// The raw value of a name in the signal's value table.
    pub fn value_of_name(&self, name: &str) -> Option<i64> {
        self.value_table
            .iter()
            .find(|(_, n)| n == name)
            .map(|(v, _)| *v)
    }
}

/// One decoded signal: its index in [`WireMessage::signals`], raw bits and physical value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SignalValue {
    /// Index in [`WireMessage::signals`].
    pub index: usize,
    /// The raw bits.
    pub bits: u64,
    /// `raw * factor + offset`.
    pub physical: f64,
}

impl WireMessage {
    /// The signal with this name.
    pub fn signal(&self, name: &str) -> Option<&WireSignal> {
        self.signals.iter().find(|s| s.name == name)
    }

    /// The index of the signal with this name.
    pub fn signal_index(&self, name: &str) -> Option<usize> {
        self.signals.iter().position(|s| s.name == name)
    }

    /// True if `sig` is present in a frame whose multiplexor holds `mux`.
    fn active(sig: &WireSignal, mux: Option<u64>) -> bool {
        match sig.mux {
            Mux::Plain | Mux::Multiplexor => true,
            Mux::Multiplexed(v) => mux == Some(v),
        }
    }

    /// The multiplexor values some signal is defined for.
    pub fn mux_values(&self) -> Vec<u64> {
        let mut out: Vec<u64> = self
            .signals
            .iter()
            .filter_map(|s| match s.mux {
                Mux::Multiplexed(v) => Some(v),
                _ => None,
            })
            .collect();
        out.sort_unstable();
        out.dedup();
        out
    }

    /// Decodes the signals present in `data`: the plain ones, the multiplexor, and the multiplexed
    /// ones of the multiplexor's value.
    ///
    /// # Errors
    /// [`DecodeError::WrongLength`] if `data` is not the message's length,
    /// [`DecodeError::UnknownMux`] if the multiplexor holds a value no multiplexed signal is defined
    /// for.
    pub fn decode(&self, data: &[u8]) -> Result<Vec<SignalValue>, DecodeError> {
        if data.len() != self.size {
            return Err(DecodeError::WrongLength {
                message: self.name.clone(),
                expected: self.size,
                actual: data.len(),
            });
        }
        let mux = self.multiplexor.map(|i| self.signals[i].bits(data));
        let values = self.mux_values();
        // A multiplexor with no multiplexed signals (every signal plain) accepts any value.
        if let Some(value) = mux
            && !values.is_empty()
            && !values.contains(&value)
        {
            return Err(DecodeError::UnknownMux {
                message: self.name.clone(),
                value,
            });
        }
        Ok(self
            .signals
            .iter()
            .enumerate()
            .filter(|(_, s)| Self::active(s, mux))
            .map(|(index, s)| {
                let bits = s.bits(data);
                SignalValue {
                    index,
                    bits,
                    physical: s.physical(bits),
                }
            })
            .collect())
    }

    /// Encodes signals by index into a payload whose unused bits are `fill` (`0xFF` sends unused bits
    /// as ones, as J1939 and `cantools --padding` do). `mux` is written to the multiplexor, if any;
    /// signals not given keep the fill bits.
    ///
    /// # Errors
    /// [`EncodeError`] for a value that does not fit, or a multiplexed signal of another value.
    pub fn encode_bits(
        &self,
        mux: Option<u64>,
        values: &[(usize, u64)],
        fill: u8,
    ) -> Result<Vec<u8>, EncodeError> {
        let mut data = vec![fill; self.size];
        if let (Some(i), Some(v)) = (self.multiplexor, mux) {
            self.signals[i].put_bits(v, &mut data);
        }
        for &(index, bits) in values {
            let Some(sig) = self.signals.get(index) else {
                continue;
            };
            if let Mux::Multiplexed(signal_mux) = sig.mux
                && mux != Some(signal_mux)
            {
                return Err(EncodeError::MuxMismatch {
                    signal: sig.name.clone(),
                    signal_mux,
                    frame_mux: mux.unwrap_or(u64::MAX),
                });
            }
            sig.put_bits(bits, &mut data);
        }
        Ok(data)
    }

    /// Encodes physical values by signal name (`fill` for unused bits, limits checked), taking the
    /// multiplexor's value from the values if it is among them.
    ///
    /// # Errors
    /// [`EncodeError`] for an unknown name, a value out of range or of another multiplexor value.
    pub fn encode_named(&self, values: &[(&str, f64)], fill: u8) -> Result<Vec<u8>, EncodeError> {
        let mut bits = Vec::with_capacity(values.len());
        let mut mux = None;
        for &(name, value) in values {
            let index = self
                .signal_index(name)
                .ok_or_else(|| EncodeError::UnknownSignal {
                    message: self.name.clone(),
                    signal: name.to_string(),
                })?;
            let b = self.signals[index].bits_of(value, true)?;
            if Some(index) == self.multiplexor {
                mux = Some(b);
            }
            bits.push((index, b));
        }
        self.encode_bits(mux, &bits, fill)
    }

    /// A data frame of this message's id with `data`.
    ///
    /// # Errors
    /// Never for a payload built by this message's encoder (at most 8 bytes).
    pub fn frame(&self, data: &[u8]) -> Result<CanFrame, crate::frame::FrameError> {
        CanFrame::new_data(self.id, data)
    }

    /// True if `frame` is a classic data frame with this message's id.
    pub fn matches(&self, frame: &CanFrame) -> bool {
        frame.kind() == FrameKind::Data && frame.id() == self.id
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const DBC_MIXED: &str = r#"VERSION ""
NS_ :
BS_:
BU_: A B
BO_ 1056 Mixed: 8 A
 SG_ Mode M : 7|4@0+ (1,0) [0|3] "" B
 SG_ Speed m0 : 3|12@0- (0.5,0) [-1024|1023] "km/h" B
 SG_ Temp m1 : 3|12@0+ (0.1,-40) [-40|369.5] "degC" B
 SG_ Flag : 56|1@1+ (1,0) [0|1] "" B
 SG_ Counter : 57|7@1+ (1,0) [0|127] "" B

BO_ 2147484161 Floaty: 8 A
 SG_ Level : 0|32@1- (1,0) [0|0] "m" B
 SG_ Big : 39|16@0+ (1,0) [0|65535] "" B

VAL_ 1056 Mode 0 "Drive" 1 "Heat" ;
SIG_VALTYPE_ 2147484161 Level : 1;
"#;

    fn mixed() -> WireDbc {
        WireDbc::parse(DBC_MIXED).expect("fixture parses")
    }

    #[test]
    fn motorola_positions_follow_the_sawtooth() {
        // Start bit 7, 12 bits: byte 0 bits 7..0 then byte 1 bits 7..4, least significant last.
        let pos = bit_positions(7, 12, ByteOrder::Motorola, 8).unwrap();
        assert_eq!(pos, vec![12, 13, 14, 15, 0, 1, 2, 3, 4, 5, 6, 7]);
        assert_eq!(bit_positions(7, 12, ByteOrder::Motorola, 1), None);
        assert_eq!(bit_positions(60, 5, ByteOrder::Intel, 8), None);
    }

    #[test]
    fn big_endian_16_bits_reads_as_network_order() {
        let dbc = mixed();
        let msg = dbc.message("Floaty").unwrap();
        let big = msg.signal("Big").unwrap();
        assert_eq!(big.bits(&[0, 0, 0, 0, 0x12, 0x34, 0, 0]), 0x1234);
    }

    #[test]
    fn ids_of_both_widths_load() {
        let dbc = mixed();
        assert_eq!(dbc.messages[0].id, CanId::Standard(0x420));
        assert_eq!(dbc.messages[1].id, CanId::Extended(0x201));
        assert_eq!(dbc.messages[1].signals[0].kind, ValueKind::Float32);
    }

    #[test]
    fn multiplexed_signals_decode_only_for_their_value() {
        let dbc = mixed();
        let msg = dbc.message("Mixed").unwrap();
        let data = msg
            .encode_named(&[("Mode", 1.0), ("Temp", 21.5), ("Counter", 9.0)], 0xFF)
            .unwrap();
        let names: Vec<(&str, f64)> = msg
            .decode(&data)
            .unwrap()
            .iter()
            .map(|v| (msg.signals[v.index].name.as_str(), v.physical))
            .collect();
        assert_eq!(names.len(), 4, "{names:?}"); // Mode, Temp, Flag (fill), Counter
        assert!(
            names
                .iter()
                .any(|&(n, v)| n == "Temp" && (v - 21.5).abs() < 1e-9)
        );
        assert!(!names.iter().any(|&(n, _)| n == "Speed"));
        assert_eq!(msg.signals[0].value_name(1), Some("Heat"));
        assert_eq!(msg.signals[0].value_of_name("Drive"), Some(0));
        assert!(matches!(
            msg.encode_named(&[("Mode", 0.0), ("Temp", 1.0)], 0),
            Err(EncodeError::MuxMismatch { .. })
        ));
        let mut bad = data.clone();
        msg.signals[0].put_bits(3, &mut bad);
        assert!(matches!(
            msg.decode(&bad),
            Err(DecodeError::UnknownMux { value: 3, .. })
        ));
    }

    #[test]
    fn values_that_do_not_fit_are_refused() {
        let dbc = mixed();
        let msg = dbc.message("Mixed").unwrap();
        let speed = msg.signal("Speed").unwrap();
        assert!(speed.bits_of(1023.0, true).is_ok());
        assert!(matches!(
            speed.bits_of(1024.5, true),
            Err(EncodeError::OutOfRange { .. })
        ));
        assert!(matches!(
            speed.bits_of(f64::NAN, false),
            Err(EncodeError::NotFinite { .. })
        ));
        assert_eq!(speed.physical(speed.bits_of(-3.5, true).unwrap()), -3.5);
    }

    #[test]
    fn unsupported_dbcs_are_refused_with_the_message_named() {
        let too_long = DBC_MIXED.replace("Counter : 57|7@1+", "Counter : 57|8@1+");
        let err = WireDbc::parse(&too_long).unwrap_err();
        assert!(
            err.to_string().contains("Mixed") && err.to_string().contains("Counter"),
            "{err}"
        );
        let no_mux = DBC_MIXED.replace("Mode M :", "Mode :");
        let err = WireDbc::parse(&no_mux).unwrap_err();
        assert!(err.to_string().contains("no multiplexor"), "{err}");
        assert!(matches!(WireDbc::parse("BO_ x"), Err(LoadError::Parse(_))));
    }
}
