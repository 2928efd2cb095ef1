//! # learner
//!
//! Owns everything at the policy's rate and slower: MCAP logging and reading,
//! data collection, the self-supervised dataset and its labels, the
//! multimodal representation (product-of-experts variational model, its
//! baselines and ablations), the policy and its TRPO training, the
//! environments of the fast path, the evaluation of the paper's experiments,
//! the live 20 Hz inference node and the command-line interface.
//!
//! It must never sit in the 1 kHz path: the controller takes its latest
//! action without waiting for it.

pub mod collect;
pub mod dataset;
pub mod env;
pub mod labels;
pub mod live;
pub mod log;
pub mod policy;
pub mod progress;
pub mod stack;
