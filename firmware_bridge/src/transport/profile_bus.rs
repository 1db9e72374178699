//! [`ProfileBus`]: any [`Bus`] speaking a machine profile's wire protocol, seen by the node above it
//! as the canonical protocol.
//!
//! Frames the node sends are translated to wire frames before the inner bus sends (and records)
//! them; received wire frames are translated back before the node sees them. A frame the profile does
//! not map, or a canonical value the wire cannot hold, is counted ([`ProfileStats`]), logged at each
//! power of two and not passed on: an unmapped wire id may coincide with a canonical one of another
//! meaning, so handing it up untranslated could be misread. The inner bus's recorder therefore writes
//! what is on the wire.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use super::{Bus, Result, TimestampedFrame, TraceClock};
use crate::frame::CanFrame;
use crate::profile::{Profile, TranslateError};

/// Frames a [`ProfileBus`] did not pass on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ProfileStats {
    /// Received wire frames the profile maps to no canonical message (or of the wrong length).
    pub unmapped_received: u64,
    /// Canonical frames the node sent that could not be put on the wire.
    pub untranslatable_sent: u64,
}

/// A profile with the counts of the frames it did not pass on: the translation of [`ProfileBus`],
/// for callers that move frames themselves (the lab's in-process harness and embedded machine).
#[derive(Debug)]
pub struct ProfileLink {
    profile: Arc<Profile>,
    unmapped_received: AtomicU64,
    untranslatable_sent: AtomicU64,
}

impl ProfileLink {
    /// A link translating through `profile`.
    pub fn new(profile: Arc<Profile>) -> Self {
        Self {
            profile,
            unmapped_received: AtomicU64::new(0),
            untranslatable_sent: AtomicU64::new(0),
        }
    }

    /// The profile.
    pub fn profile(&self) -> &Profile {
        &self.profile
    }

    /// Logs [`ProfileLink::stats`] with the profile's file (at the end of a run).
    pub fn log_stats(&self) {
        let stats = self.stats();
        tracing::info!(
            profile = self.profile.origin(),
            unmapped_received = stats.unmapped_received,
            untranslatable_sent = stats.untranslatable_sent,
            "machine profile"
        );
    }

    /// What was not passed on so far.
    pub fn stats(&self) -> ProfileStats {
        ProfileStats {
            unmapped_received: self.unmapped_received.load(Ordering::Relaxed),
            untranslatable_sent: self.untranslatable_sent.load(Ordering::Relaxed),
        }
    }

    /// The wire frame of a canonical frame to send; `None` (counted, logged at each power of two)
    /// when the profile cannot carry it.
    pub fn to_wire(&self, frame: &CanFrame) -> Option<CanFrame> {
        self.passed(
            self.profile.to_wire(frame),
            &self.untranslatable_sent,
            "frame not sent, the profile cannot carry it",
        )
    }

    /// The canonical frame of a received wire frame; `None` (counted, logged at each power of two)
    /// for a frame the profile does not map.
    pub fn from_wire(&self, frame: &CanFrame) -> Option<CanFrame> {
        self.passed(
            self.profile.from_wire(frame),
            &self.unmapped_received,
            "frame rejected",
        )
    }

    fn passed(
        &self,
        translated: std::result::Result<CanFrame, TranslateError>,
        counter: &AtomicU64,
        what: &str,
    ) -> Option<CanFrame> {
        match translated {
            Ok(frame) => Some(frame),
            // An address claim for a bus without J1939 addresses: nothing to send, nothing wrong.
            Err(TranslateError::NotOnThisBus(_)) => None,
            Err(e) => {
                let n = counter.fetch_add(1, Ordering::Relaxed) + 1;
                if n.is_power_of_two() {
                    tracing::warn!(profile = self.profile.origin(), count = n, "{what}: {e}");
                }
                None
            }
        }
    }
}

/// A bus translating between the canonical protocol (above) and a profile's wire protocol (below).
#[derive(Debug)]
pub struct ProfileBus<B> {
    inner: B,
    link: ProfileLink,
}

impl<B: Bus> ProfileBus<B> {
    /// Wraps `inner`.
    pub fn new(inner: B, profile: Arc<Profile>) -> Self {
        Self {
            inner,
            link: ProfileLink::new(profile),
        }
    }

    /// The bus below.
    pub fn inner(&self) -> &B {
        &self.inner
    }

    /// The profile.
    pub fn profile(&self) -> &Profile {
        self.link.profile()
    }

    /// Logs [`ProfileBus::stats`] with the profile's file (at the end of a run).
    pub fn log_stats(&self) {
        self.link.log_stats();
    }

    /// What was not passed on so far.
    pub fn stats(&self) -> ProfileStats {
        self.link.stats()
    }
}

impl<B: Bus> Bus for ProfileBus<B> {
    async fn send(&self, frame: CanFrame) -> Result<()> {
        match self.link.to_wire(&frame) {
            Some(wire) => self.inner.send(wire).await,
            None => Ok(()),
        }
    }

    async fn recv(&self) -> Result<TimestampedFrame> {
        loop {
            let received = self.inner.recv().await?;
            if let Some(frame) = self.link.from_wire(&received.frame) {
                return Ok(TimestampedFrame {
                    timestamp_ns: received.timestamp_ns,
                    frame,
                });
            }
        }
    }

    fn now_ns(&self) -> u64 {
        self.inner.now_ns()
    }

    fn interface(&self) -> &str {
        self.inner.interface()
    }

    fn trace_clock(&self) -> TraceClock {
        self.inner.trace_clock()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::messages::{JointAngles, Message};
    use crate::transport::InProcessBus;

    const EXAMPLE: &str = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/other_gateway.toml"
    );

    #[tokio::test]
    async fn both_ends_see_canonical_frames_and_the_bus_carries_wire_frames() {
        let profile = Arc::new(Profile::load(std::path::Path::new(EXAMPLE)).expect("loads"));
        let bus = InProcessBus::with_wall_clock("vcan0");
        let gateway = ProfileBus::new(bus.attach(), profile.clone());
        let controller = ProfileBus::new(bus.attach(), profile.clone());
        let sniffer = bus.attach();
        let angles = Message::JointAngles(JointAngles {
            boom_rad: 0.5,
            stick_rad: -1.0,
            bucket_rad: 0.25,
            swing_rad: 0.0,
        })
        .encode()
        .expect("encodes");
        gateway.send(angles).await.expect("sends");
        let on_wire = sniffer.recv().await.expect("the wire frame");
        assert_eq!(on_wire.frame.id(), crate::CanId::Standard(0x301));
        let got = controller.recv().await.expect("a canonical frame");
        assert_eq!(got.frame.id(), angles.id());
        let decoded = Message::decode(&got.frame).expect("decodes");
        let Message::JointAngles(a) = decoded.message else {
            panic!("{decoded:?}")
        };
        assert!((a.boom_rad - 0.5).abs() < 1e-4 && (a.bucket_rad - 0.25).abs() < 1e-4);

        // An unmapped frame is counted, not passed up; the next mapped one is.
        sniffer
            .send(CanFrame::new_standard(0x7FF, &[0; 8]).expect("valid"))
            .expect("sends");
        gateway.send(angles).await.expect("sends");
        let got = controller.recv().await.expect("the mapped frame");
        assert_eq!(got.frame.id(), angles.id());
        assert_eq!(controller.stats().unmapped_received, 1);

        // A canonical frame the profile cannot carry is counted, not sent.
        let foreign = CanFrame::new_extended(0x18FF_AA27, &[0; 8]).expect("valid");
        controller.send(foreign).await.expect("not an error");
        assert_eq!(controller.stats().untranslatable_sent, 1);
    }
}
