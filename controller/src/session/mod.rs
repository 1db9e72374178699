//! A session of many actions on one node: the driver that runs it step by step, the planner that
//! supplies its actions, the serialized types a checkpoint holds, and the state file a killed session
//! resumes from.

pub mod driver;
pub mod planned;
pub mod session_state;
pub mod snapshot;
pub mod state_file;
