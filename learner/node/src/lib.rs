//! # learner-node
//!
//! What the robot PC runs at the policy's rate and slower, apart from
//! anything that trains: proprioception ([`proprio`]), the observations a
//! policy acts on ([`observe`]), the scripted policies ([`policy`]) and the
//! collection mix ([`mix`]), the deployed policy's file format and its
//! inference ([`deploy`]), the representation's CPU inference ([`repr`]),
//! MCAP logging and reading ([`log`]), the live 20 Hz node ([`live`],
//! [`calibrated`]), the stack's process orchestrator ([`stack`]), progress
//! bars ([`progress`]) and the node's command line ([`cli`]; the
//! `policy-node` binary).
//!
//! It must not depend on anything that trains: no burn (neither autodiff
//! nor optimisers nor its tensors), no dataset builder, no RL algorithm.
//! The training toolkit (the `learner` crate) builds on it and converts its
//! trained models into the [`deploy`] format; never the reverse. The node
//! never sits in the 1 kHz path: the controller takes its latest action
//! without waiting for it. See docs/architecture.md.

pub mod calibrated;
pub mod cli;
pub mod deploy;
pub mod live;
pub mod log;
pub mod mix;
pub mod observe;
pub mod policy;
pub mod progress;
pub mod proprio;
pub mod repr;
pub mod stack;
