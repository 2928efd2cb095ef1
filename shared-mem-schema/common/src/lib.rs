//! # stack-common
//!
//! Small utilities that the simulator, the learner and the node share, so
//! that none of them reaches into another for them: the one seeded random
//! generator ([`rng`]) and PNG files for people ([`png`]). Configuration
//! field errors are `shared_mem_schema::config`'s.
//!
//! Must not: depend on any other crate of ours, or hold domain logic
//! (physics, control, learning).

pub mod png;
pub mod rng;
