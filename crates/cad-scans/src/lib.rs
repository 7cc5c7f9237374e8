//! Scanner clouds of real CAD, made independently of the project's own scan generator, and the
//! trials that align them with ips and with peers (Open3D, small_gicp) in the same run
//! (issue 20, docs/cad-scan-trials.md).
//!
//! - [`scanner`]: a ray-casting range scanner over a whole scene (occlusion, range noise along
//!   the ray, mixed pixels at depth edges, spurious returns);
//! - [`scenes`]: the parts (shipped meshes, the ABB IRB 1600's from outside the repository) and
//!   the seeded scenes: a part standing or lying on a floor beside a box, 2-3 scanners;
//! - [`robot`]: a whole robot (its URDF's links posed by forward kinematics) scanned the same
//!   way, for the robot fit's trials (`robot-scans`);
//! - [`files`], [`trials`], [`peers`], [`table`]: the corpus written to files, ips and the peers
//!   run on it, every pose scored by the thesis's pose distance, one table.

pub mod files;
pub mod peers;
pub mod robot;
pub mod scanner;
pub mod scenes;
pub mod table;
pub mod trials;

pub use scanner::SceneError;

/// A binary's end: the output on stdout and success, or the message on stderr after the
/// program's name and exit code 2 (bad input).
pub fn finish(program: &str, result: Result<String, String>) -> std::process::ExitCode {
    match result {
        Ok(text) => {
            println!("{text}");
            std::process::ExitCode::SUCCESS
        }
        Err(message) => {
            eprintln!("{program}: {message}");
            std::process::ExitCode::from(2)
        }
    }
}
