//! The I/O around the control step: the real-time loop over SocketCAN, the operator's control socket
//! and the range-scan client. Tokio drives these; the step itself never waits.

pub mod operator;
pub mod run;
pub mod scan_client;
pub mod sd_notify;
