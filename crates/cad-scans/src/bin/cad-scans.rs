//! `cad-scans`: the CAD scan corpus aligned by ips and by the peers in one run, one table.

use std::path::PathBuf;
use std::process::ExitCode;

use cad_scans::peers::{PEERS, default_script, run_peers};
use cad_scans::scanner::ScanNoise;
use cad_scans::scenes::{DEFAULT_ABB_DIR, Part, check_metres, parts_in, shipped_parts};
use cad_scans::table::{IPS, IPS_LOCAL, Scored, markdown, records, rows};
use cad_scans::trials::{CorpusOptions, Trial, prepare_trials, run_ips, write_manifest};
use clap::Parser;

/// Scans real CAD with a ray-casting scanner (2-3 positions, occlusion by a floor and a box,
/// 0.5 mm range noise, mixed pixels at depth edges, 10 % outliers), displaces each start by the
/// thesis's scheme, aligns it with ips (as `ips align-cloud` does) and with Open3D and
/// small_gicp in the same run, and prints one Markdown table: successes (thesis pose distance
/// under 1 mm) per delta, median pose errors and median times.
///
/// Parts: the meshes shipped in crates/cad-scans/meshes (xArm7 and SO-ARM100 links), the ABB
/// IRB 1600 links read from --abb-dir when that folder exists, and your own (--mesh-dir).
/// Peers: run scripts/peer-env.sh once (it installs Open3D and small_gicp in .venv), or pass
/// --no-peers. Progress goes to stderr; the table (or --json) to stdout.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum IpsMode {
    Full,
    Local,
}

#[derive(Debug, Parser)]
#[command(name = "cad-scans", version)]
struct Args {
    /// Deltas in mm (the thesis's bound on the start error; each trial's start is displaced
    /// within it).
    #[arg(long, value_delimiter = ',', default_value = "50,100,200,500,1000")]
    deltas_mm: Vec<f64>,
    /// Scans per delta; each scan is its own scene, the parts taken in turn.
    #[arg(long, default_value_t = 4)]
    scans: usize,
    #[arg(long, default_value_t = 20)]
    seed: u64,
    /// Folder of the ABB IRB 1600 link meshes (STL in metres); skipped when it does not exist
    /// [default: $CAD_SCANS_ABB_DIR, else ../shared/data/abb_irb1600/abb_irb1600_support/meshes/irb1600/visual].
    #[arg(long)]
    abb_dir: Option<PathBuf>,
    /// Only the meshes shipped in the repository.
    #[arg(long)]
    no_abb: bool,
    /// A folder of parts of your own: every STL, OBJ or PLY file in it, in metres, named
    /// `<folder>_<file stem>` (repeat for more folders). With --parts naming them, a corpus of
    /// parts the project was never tuned on.
    #[arg(long, value_name = "DIR")]
    mesh_dir: Vec<PathBuf>,
    /// Only parts whose name contains one of these (comma-separated).
    #[arg(long, value_delimiter = ',')]
    parts: Vec<String>,
    /// Where the scenes' files go (cloud.ply, part.stl, scene.json, truth.json per trial).
    #[arg(long, default_value = "target/cad-scans")]
    out: PathBuf,
    /// Python of the venv scripts/peer-env.sh made.
    #[arg(long, default_value = ".venv/bin/python")]
    python: PathBuf,
    /// The peer script [default: the one shipped with this crate].
    #[arg(long)]
    peer_script: Option<PathBuf>,
    /// Threads each peer may use (ips uses rayon's default, all cores).
    #[arg(long, default_value_t = 2)]
    peer_threads: usize,
    /// How ips runs, each a column of its own: `full` as `ips align-cloud` (the exploration and
    /// the uniqueness test), `local` as `ips align-cloud --local` (the schedule from the start
    /// and the polish only: the same class of method as the peers), or both (`full,local`).
    #[arg(long, value_delimiter = ',', default_value = "full")]
    ips: Vec<IpsMode>,
    /// The scanner's range noise (standard deviation along each ray), mm.
    #[arg(long, default_value_t = 0.5, value_parser = positive_mm)]
    range_noise_mm: f64,
    /// Only ips: no Python.
    #[arg(long)]
    no_peers: bool,
    /// Print one JSON document (rows and every trial) instead of the table.
    #[arg(long)]
    json: bool,
}

/// A noise in mm: finite and not negative.
fn positive_mm(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(mm) if mm.is_finite() && mm >= 0.0 => Ok(mm),
        _ => Err(format!(
            "expected a distance in mm (finite, 0 or more), got '{text}'"
        )),
    }
}

fn main() -> ExitCode {
    cad_scans::finish("cad-scans", run(&Args::parse()))
}

fn load_parts(args: &Args) -> Result<Vec<Part>, String> {
    let mut parts = shipped_parts().map_err(|e| e.to_string())?;
    if !args.no_abb {
        let abb_dir = args.abb_dir.clone().unwrap_or_else(|| {
            std::env::var_os("CAD_SCANS_ABB_DIR")
                .map_or_else(|| PathBuf::from(DEFAULT_ABB_DIR), PathBuf::from)
        });
        if abb_dir.is_dir() {
            parts.extend(parts_in(&abb_dir, "irb1600_").map_err(|e| e.to_string())?);
        } else {
            eprintln!(
                "cad-scans: no ABB meshes at '{}' (--abb-dir or CAD_SCANS_ABB_DIR): shipped meshes only",
                abb_dir.display()
            );
        }
    }
    for dir in &args.mesh_dir {
        let folder = dir
            .canonicalize()
            .ok()
            .and_then(|d| d.file_name().map(|n| n.to_string_lossy().into_owned()))
            .unwrap_or_else(|| "mesh".to_owned());
        let own = parts_in(dir, &format!("{folder}_")).map_err(|e| e.to_string())?;
        for part in &own {
            check_metres(part).map_err(|e| e.to_string())?;
        }
        parts.extend(own);
    }
    let mut names: Vec<&str> = parts.iter().map(|p| p.name.as_str()).collect();
    names.sort_unstable();
    if let Some(twice) = names.windows(2).find(|pair| pair[0] == pair[1]) {
        return Err(format!(
            "two parts are named '{}': put files of the same name in folders of different names",
            twice[0]
        ));
    }
    if !args.parts.is_empty() {
        parts.retain(|p| args.parts.iter().any(|want| p.name.contains(want.as_str())));
    }
    if parts.is_empty() {
        return Err("no part matches --parts".to_owned());
    }
    Ok(parts)
}

fn run(args: &Args) -> Result<String, String> {
    let parts = load_parts(args)?;
    let names: Vec<&str> = parts.iter().map(|p| p.name.as_str()).collect();
    eprintln!("cad-scans: parts {}", names.join(", "));
    let options = CorpusOptions {
        deltas_m: args.deltas_mm.iter().map(|d| d * 1e-3).collect(),
        scans_per_delta: args.scans,
        seed: args.seed,
        noise: ScanNoise {
            range_sigma_m: args.range_noise_mm * 1e-3,
            ..ScanNoise::default()
        },
        out_dir: args.out.clone(),
    };
    let trials = prepare_trials(&parts, &options, |done, total| {
        eprint!("\rcad-scans: scanned {done}/{total}");
    })
    .map_err(|e| e.to_string())?;
    eprintln!();
    let mut local_runs: Vec<bool> = Vec::new();
    for mode in &args.ips {
        let local = *mode == IpsMode::Local;
        if !local_runs.contains(&local) {
            local_runs.push(local);
        }
    }
    let mut methods: Vec<String> = local_runs
        .iter()
        .map(|&local| if local { IPS_LOCAL } else { IPS }.to_owned())
        .collect();
    let mut outcomes: Vec<Vec<Option<cad_scans::trials::Outcome>>> = Vec::new();
    for (index, trial) in trials.iter().enumerate() {
        let mut row = Vec::new();
        for &local in &local_runs {
            let outcome = run_ips(trial, local);
            // One line a trial: a long run's results can be read before its table.
            eprintln!(
                "cad-scans: {} {}/{}: {} at {:.0} mm: {:.2} mm off in {:.2} s{}{}",
                if local { IPS_LOCAL } else { IPS },
                index + 1,
                trials.len(),
                trial.part,
                trial.delta_m * 1e3,
                outcome.error_m(trial) * 1e3,
                outcome.time_s,
                if outcome.ambiguous { ", ambiguous" } else { "" },
                if outcome.refused.is_some() {
                    ", refused"
                } else {
                    ""
                },
            );
            row.push(Some(outcome));
        }
        outcomes.push(row);
    }
    if !args.no_peers {
        let manifest = args.out.join("manifest.json");
        write_manifest(&manifest, &trials).map_err(|e| format!("'{}': {e}", manifest.display()))?;
        let script = args.peer_script.clone().unwrap_or_else(default_script);
        let peers = run_peers(&args.python, &script, &manifest, args.peer_threads)
            .map_err(|e| e.to_string())?;
        for peer in PEERS {
            methods.push(peer.to_owned());
            for (trial, row) in trials.iter().zip(&mut outcomes) {
                row.push(peers.get(&trial.id).and_then(|m| m.get(peer)).cloned());
            }
        }
    }
    report(args, &trials, &outcomes, &methods)
}

fn report(
    args: &Args,
    trials: &[Trial],
    outcomes: &[Vec<Option<cad_scans::trials::Outcome>>],
    methods: &[String],
) -> Result<String, String> {
    let scored: Vec<Scored> = trials
        .iter()
        .zip(outcomes)
        .map(|(trial, outcomes)| Scored {
            trial,
            outcomes: outcomes.clone(),
        })
        .collect();
    let rows = rows(&scored, methods);
    let document = serde_json::json!({
        "seed": args.seed,
        "scans_per_delta": args.scans,
        "rows": rows,
        "trials": records(&scored, methods),
    });
    let json = serde_json::to_string(&document).map_err(|e| e.to_string())?;
    let table = markdown(&rows);
    // Both forms beside the scenes, so a long run's table survives a lost terminal.
    for (name, text) in [("results.json", &json), ("table.md", &table)] {
        let path = args.out.join(name);
        std::fs::write(&path, text).map_err(|e| format!("'{}': {e}", path.display()))?;
    }
    Ok(if args.json { json } else { table })
}

#[cfg(test)]
mod tests {
    use super::positive_mm;

    #[test]
    fn the_range_noise_is_a_distance_in_mm_and_anything_else_is_refused() {
        assert_eq!(positive_mm("0.2"), Ok(0.2));
        assert_eq!(positive_mm("0"), Ok(0.0));
        for bad in ["-0.5", "NaN", "inf", "half"] {
            let refused = positive_mm(bad).unwrap_err();
            assert!(refused.contains(bad), "{refused}");
        }
    }
}
