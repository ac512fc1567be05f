//! The subcommands of the `meniscus` command line, one module each ([`reconstruct`],
//! [`archive`]), with what they share: the flags of a USD stage and of a frame
//! selection ([`shared`]) and how a command fails ([`failure`]). They translate flags
//! into the library's settings and report what it did; the work is the library's.

pub(crate) mod archive;
pub(crate) mod failure;
pub(crate) mod reconstruct;
pub(crate) mod shared;

pub(crate) use failure::Failure;
pub(crate) use shared::{FarmArgs, StageArgs};
