//! One file (or folder) per `ips` subcommand, each owning its arguments, its run and its
//! output. A command returns the text it prints; errors carry their exit code ([`crate::CliError`]).

pub mod align;
pub mod align_cloud;
pub mod align_robot;
pub mod demo;
pub mod diagnose;
pub mod fk;
pub mod kinematics;
pub mod plan;
pub mod serve;
pub mod service;
pub mod trials;
