//! The gateway on a bus with the [`embedded_can`] traits: a microcontroller's CAN driver (or any
//! other implementation of [`embedded_can::nb::Can`]) feeds it and carries its status out.
//!
//! The firmware's main loop on a microcontroller, with a 1 kHz timer interrupt or a polled timer:
//!
//! ```text
//! every tick:   gateway.poll(&mut can, now, MAX_FRAMES_PER_TICK)   (frames in)
//!               let out = gateway.tick(now, resolvers.angles());   (watchdog, position loop)
//!               valves.drive(out.valve_commands);
//!               if let Some(f) = gateway.take_claim_frame() { can.transmit(&f) }  (address claim)
//!               if let Some(f) = gateway.dm1_frame()? { can.transmit(&f) }   (DM1: 1 s, on a change)
//! every 50 ms:  for f in gateway.status_frames()?.into_iter().flatten() { can.transmit(&f) }
//!                                                   (status and session out, once the claim stands)
//! ```
//!
//! A driver's receive error (overrun, bus-off, error passive, ...) is a bus error: while armed it
//! latches `BUS_ERROR` (valves neutral) and it counts as a rejected frame, as a Linux CAN error frame
//! does on SocketCAN.

use crate::frame::CanFrame;
use crate::gateway::{FrameVerdict, Gateway};
use crate::messages::{EncodeError, Message};
use crate::time::ClockReading;

/// Why the status frames could not be built.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum StatusFrameError {
    /// A value does not fit its signal (the counters saturate, so this does not happen in practice).
    #[error(transparent)]
    Encode(#[from] EncodeError),
    /// The driver's frame type refused a classic extended data frame.
    #[error("the CAN driver's frame type cannot hold id {id:#010X} with {len} data bytes")]
    FrameType {
        /// The 29-bit id.
        id: u32,
        /// Data bytes.
        len: usize,
    },
}

/// What one [`Gateway::poll`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PollCounts {
    /// Frames received and handed to the gateway.
    pub frames: u32,
    /// Receive errors reported by the driver.
    pub errors: u32,
}

impl Gateway {
    /// Handles a frame of any [`embedded_can::Frame`] type (see [`Gateway::on_frame`]).
    pub fn on_can_frame<F: embedded_can::Frame>(
        &mut self,
        frame: &F,
        now: impl Into<ClockReading>,
    ) -> FrameVerdict {
        match CanFrame::from_frame(frame) {
            Some(frame) => self.on_frame(&frame, now),
            // A length no classic frame has: the driver handed over something that is not CAN.
            None => self.on_bus_error(now),
        }
    }

    /// A receive error of the bus driver at `now`: `BUS_ERROR` while armed, counted as rejected.
    pub fn on_bus_error(&mut self, now: impl Into<ClockReading>) -> FrameVerdict {
        // The error-frame path of `on_frame` (class bits are not part of the decision).
        match CanFrame::new_error(0, [0; 8]) {
            Ok(error_frame) => self.on_frame(&error_frame, now),
            Err(_) => FrameVerdict::Rejected,
        }
    }

    /// Receives what `can` has pending, at most `max_frames` frames and errors (a babbling node
    /// cannot hold the tick up), and hands each to the gateway stamped `now`.
    pub fn poll<C: embedded_can::nb::Can>(
        &mut self,
        can: &mut C,
        now: impl Into<ClockReading>,
        max_frames: u32,
    ) -> PollCounts {
        let now = now.into();
        let mut counts = PollCounts::default();
        while counts.frames + counts.errors < max_frames {
            match can.receive() {
                Ok(frame) => {
                    counts.frames += 1;
                    self.on_can_frame(&frame, now);
                }
                Err(nb::Error::WouldBlock) => break,
                Err(nb::Error::Other(_)) => {
                    counts.errors += 1;
                    self.on_bus_error(now);
                }
            }
        }
        counts
    }

    /// The two frames of the 20 Hz report, built by any [`embedded_can::Frame`] type: the status
    /// (advancing its alive counter, [`Gateway::next_status`]) and the session nonce. `None` (and the
    /// counter unchanged) while the address claim does not stand ([`Gateway::may_transmit`]).
    ///
    /// # Errors
    /// [`StatusFrameError`]; the alive counter has advanced all the same.
    pub fn status_frames<F: embedded_can::Frame>(
        &mut self,
    ) -> Result<Option<[F; 2]>, StatusFrameError> {
        if !self.may_transmit() {
            return Ok(None);
        }
        let status = Message::GatewayStatus(self.next_status()).encode()?;
        let session = Message::GatewaySession(self.session()).encode()?;
        Ok(Some([to_frame(&status)?, to_frame(&session)?]))
    }

    /// The J1939-73 DM1 frame (PGN 65226) due now ([`Gateway::dm1_due`]): call it at every tick; it
    /// is `Some` once per second and at a change of the fault bits. `None` while the address claim does
    /// not stand.
    ///
    /// # Errors
    /// [`StatusFrameError`].
    pub fn dm1_frame<F: embedded_can::Frame>(&mut self) -> Result<Option<F>, StatusFrameError> {
        if !self.may_transmit() {
            return Ok(None);
        }
        let Some(dm1) = self.dm1_due() else {
            return Ok(None);
        };
        let frame = Message::Dm1(dm1).encode_from(self.address_claim().address())?;
        Ok(Some(to_frame(&frame)?))
    }
}

/// `frame` as another [`embedded_can::Frame`] type (a classic data frame: always representable).
fn to_frame<F: embedded_can::Frame>(frame: &CanFrame) -> Result<F, StatusFrameError> {
    F::new(embedded_can::Frame::id(frame), frame.data()).ok_or(StatusFrameError::FrameType {
        id: frame.id().raw(),
        len: frame.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gateway::VALVES;
    use crate::messages::{
        AuxValveCommand, ControllerHeartbeat, GatewayFaults, GatewayMode, RequestedMode, Valve,
    };
    use crate::secoc::{Sealer, SeededNonceSource, SessionKey};
    use crate::time::Instant;
    use std::collections::VecDeque;
    use std::vec::Vec;

    /// A driver's frame type, not the crate's: what a HAL hands over.
    #[derive(Debug, Clone, PartialEq)]
    struct HalFrame {
        id: embedded_can::Id,
        data: Vec<u8>,
    }

    impl embedded_can::Frame for HalFrame {
        fn new(id: impl Into<embedded_can::Id>, data: &[u8]) -> Option<Self> {
            (data.len() <= 8).then(|| Self {
                id: id.into(),
                data: data.to_vec(),
            })
        }
        fn new_remote(_id: impl Into<embedded_can::Id>, _dlc: usize) -> Option<Self> {
            None
        }
        fn is_extended(&self) -> bool {
            matches!(self.id, embedded_can::Id::Extended(_))
        }
        fn is_remote_frame(&self) -> bool {
            false
        }
        fn id(&self) -> embedded_can::Id {
            self.id
        }
        fn dlc(&self) -> usize {
            self.data.len()
        }
        fn data(&self) -> &[u8] {
            &self.data
        }
    }

    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    struct Overrun;

    impl embedded_can::Error for Overrun {
        fn kind(&self) -> embedded_can::ErrorKind {
            embedded_can::ErrorKind::Overrun
        }
    }

    /// A CAN controller's receive FIFO and transmit mailbox, in memory.
    #[derive(Default)]
    struct Fifo {
        rx: VecDeque<Result<HalFrame, Overrun>>,
        tx: Vec<HalFrame>,
    }

    impl embedded_can::nb::Can for Fifo {
        type Frame = HalFrame;
        type Error = Overrun;
        fn transmit(&mut self, frame: &HalFrame) -> nb::Result<Option<HalFrame>, Overrun> {
            self.tx.push(frame.clone());
            Ok(None)
        }
        fn receive(&mut self) -> nb::Result<HalFrame, Overrun> {
            match self.rx.pop_front() {
                Some(Ok(f)) => Ok(f),
                Some(Err(e)) => Err(nb::Error::Other(e)),
                None => Err(nb::Error::WouldBlock),
            }
        }
    }

    fn hal(frame: &CanFrame) -> HalFrame {
        to_frame(frame).unwrap()
    }

    #[test]
    fn arms_drives_and_reports_over_an_embedded_can_driver() {
        let mut g = Gateway::with_default_config(&mut SeededNonceSource(0));
        let mut can = Fifo::default();
        let mut sealer = Sealer::new(&SessionKey::PUBLIC);
        // The address claim goes first; no report until it has stood for 250 ms.
        g.tick(Instant::ZERO, None);
        let claim = g.take_claim_frame().unwrap();
        assert_eq!(claim.id().raw(), 0x18EE_FF80);
        assert!(g.status_frames::<HalFrame>().unwrap().is_none());
        g.tick(Instant::from_millis(250), None);
        // The controller learns the session from the status report.
        let [_, session]: [HalFrame; 2] = g.status_frames().unwrap().unwrap();
        let session = Message::decode(&CanFrame::from_frame(&session).unwrap()).unwrap();
        let Message::GatewaySession(s) = session.message else {
            panic!("not a session frame");
        };
        sealer.set_session(s.session_id);
        let hb = ControllerHeartbeat {
            mode: RequestedMode::ArmValve,
            alive_counter: 0,
        };
        let cmd = AuxValveCommand::from_fraction(Valve::Boom, 0.5).unwrap();
        for m in [
            Message::ControllerHeartbeat(hb),
            Message::AuxValveCommand(cmd),
        ] {
            can.rx.push_back(Ok(hal(&sealer.seal(&m).unwrap())));
        }
        let now = Instant::from_millis(251);
        let counts = g.poll(&mut can, now, 16);
        assert_eq!(
            counts,
            PollCounts {
                frames: 2,
                errors: 0
            }
        );
        let out = g.tick(now, None);
        assert_eq!(out.valve_commands[0], 0.5);
        assert_eq!(out.status.mode, GatewayMode::ArmedValve);
        // The report goes out through the driver and decodes.
        for f in g.status_frames::<HalFrame>().unwrap().into_iter().flatten() {
            embedded_can::nb::Can::transmit(&mut can, &f).unwrap();
        }
        let sent = Message::decode(&CanFrame::from_frame(&can.tx[0]).unwrap()).unwrap();
        let Message::GatewayStatus(status) = sent.message else {
            panic!("not a status frame");
        };
        assert_eq!(status.mode, GatewayMode::ArmedValve);
        // A receive overrun while armed is a bus error: neutral.
        can.rx.push_back(Err(Overrun));
        let counts = g.poll(&mut can, Instant::from_millis(252), 16);
        assert_eq!(
            counts,
            PollCounts {
                frames: 0,
                errors: 1
            }
        );
        let out = g.tick(Instant::from_millis(252), None);
        assert_eq!(out.valve_commands, [0.0; VALVES]);
        assert!(out.status.faults.contains(GatewayFaults::BUS_ERROR));
    }

    #[test]
    fn poll_stops_at_its_budget() {
        let mut g = Gateway::with_default_config(&mut SeededNonceSource(0));
        let mut can = Fifo::default();
        let junk = CanFrame::new_extended(0x18FE_EE00, &[1, 2, 3]).unwrap();
        for _ in 0..10 {
            can.rx.push_back(Ok(hal(&junk)));
        }
        let counts = g.poll(&mut can, Instant::ZERO, 4);
        assert_eq!(counts.frames, 4);
        assert_eq!(can.rx.len(), 6);
        assert_eq!(g.frame_counts(), (4, 0));
    }
}
