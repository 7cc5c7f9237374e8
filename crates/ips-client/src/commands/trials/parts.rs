//! `ips trials`: the thesis's AlignmentTests for Point Set Alignment, the thesis's method and ours
//! side by side on the same seeded displacements.

use align_core::registration::pca::{DeltaSchedule, PcaOptions, PcaStep};
use align_core::registration::psa::{PsaMethod, PsaOptions, Search};
use align_core::trials::clouds::pca_trial_scan;
use align_core::trials::parts::{TestPart, step_block};
use align_core::trials::{TouchSetup, TrialRow, run_pca_trials, run_psa_trials};
use serde::Serialize;

use super::args::TrialsArgs;
use crate::BadInput;

#[derive(Debug, Serialize)]
pub struct TrialsOutput {
    pub part: String,
    pub trials_per_delta: usize,
    pub seed: u64,
    pub tables: Vec<TrialTable>,
}

#[derive(Debug, Serialize)]
pub struct TrialTable {
    pub touches: usize,
    pub face_hints: bool,
    pub method: String,
    pub rows: Vec<TrialRowJson>,
}

#[derive(Debug, Serialize)]
pub struct TrialRowJson {
    pub delta_mm: f64,
    pub succeeded: usize,
    pub failed: usize,
    pub ambiguous: usize,
    pub mean_iterations: f64,
    pub mean_error_mm: f64,
    pub mean_time_s: f64,
}

impl From<&TrialRow> for TrialRowJson {
    fn from(row: &TrialRow) -> Self {
        Self {
            delta_mm: row.delta_m * 1e3,
            succeeded: row.succeeded,
            failed: row.failed,
            ambiguous: row.ambiguous,
            mean_iterations: row.mean_iterations,
            mean_error_mm: row.mean_error_m * 1e3,
            mean_time_s: row.mean_time_s,
        }
    }
}

/// The thesis's PSA: SVD steps, one local alignment, N = 19, no coherence.
pub fn thesis_options() -> PsaOptions {
    PsaOptions {
        method: PsaMethod::PointToPoint,
        search: Search::Local,
        coherence: false,
        tolerance_m: 1e-6,
        ..PsaOptions::default()
    }
}

/// Ours: point-to-plane steps, coherence, global multi-start with ambiguity detection.
pub fn our_options() -> PsaOptions {
    PsaOptions::default()
}

struct Configuration {
    touches: usize,
    face_hints: bool,
    method: &'static str,
    options: PsaOptions,
}

/// The thesis's PCA: SVD steps, its eq. 33 schedule, voxel-centroid keypoints, no exploration,
/// no polishing run.
pub fn thesis_pca_options() -> PcaOptions {
    PcaOptions {
        step: PcaStep::PointToPoint,
        schedule: DeltaSchedule::Cosine,
        voxel_centroids: true,
        starts: 0,
        polish: false,
        // Its stopping criterion (2.1.4): the last 19 poses within the tolerance.
        window: 19,
        // Its loop matches every band exactly, from delta0.
        wide_band_slack: false,
        local_band_within_radius: false,
        ..PcaOptions::default()
    }
}

fn run_pca(
    args: &TrialsArgs,
    part: &TestPart,
    deltas_m: &[f64],
    mut progress: impl FnMut(&str),
) -> Vec<TrialTable> {
    let scan = pca_trial_scan();
    [
        ("thesis", thesis_pca_options()),
        ("ours", PcaOptions::default()),
    ]
    .into_iter()
    .map(|(method, options)| {
        let rows = run_pca_trials(
            part,
            &scan,
            &options,
            deltas_m,
            args.trials,
            args.seed,
            |delta_m, trial| {
                if trial + 1 == args.trials {
                    progress(&format!("PCA {method}: delta {:.0} mm done", delta_m * 1e3));
                }
            },
        );
        TrialTable {
            touches: 0,
            face_hints: false,
            method: method.to_owned(),
            rows: rows.iter().map(TrialRowJson::from).collect(),
        }
    })
    .collect()
}

pub fn run(args: &TrialsArgs, mut progress: impl FnMut(&str)) -> Result<TrialsOutput, BadInput> {
    let deltas_mm = crate::parse_number_list(&args.deltas, "--deltas")?;
    if let Some(bad) = deltas_mm.iter().find(|d| **d <= 0.0) {
        return Err(BadInput(format!(
            "--deltas: {bad} is not a positive distance in mm"
        )));
    }
    let deltas_m: Vec<f64> = deltas_mm.iter().map(|d| d * 1e-3).collect();
    if args.trials == 0 {
        return Err(BadInput("--trials must be at least 1".to_owned()));
    }
    let part: TestPart = step_block().map_err(BadInput::new)?;
    if args.pca {
        return Ok(TrialsOutput {
            part: part.name.clone(),
            trials_per_delta: args.trials,
            seed: args.seed,
            tables: run_pca(args, &part, &deltas_m, progress),
        });
    }
    let touch_counts: Vec<usize> = match args.touches {
        Some(count) if (6..=part.touches.len()).contains(&count) => vec![count],
        Some(count) => {
            return Err(BadInput(format!(
                "--touches {count}: the part's touch plan has 6 to {} touches",
                part.touches.len()
            )));
        }
        None => vec![6, 9],
    };
    let mut configurations = Vec::new();
    for &touches in &touch_counts {
        configurations.push(Configuration {
            touches,
            face_hints: false,
            method: "thesis",
            options: thesis_options(),
        });
        configurations.push(Configuration {
            touches,
            face_hints: false,
            method: "ours",
            options: our_options(),
        });
        configurations.push(Configuration {
            touches,
            face_hints: false,
            method: "ours-no-coherence",
            options: PsaOptions {
                coherence: false,
                ..our_options()
            },
        });
        configurations.push(Configuration {
            touches,
            face_hints: true,
            method: "ours+face-hints",
            options: our_options(),
        });
    }
    let total = configurations.len() * deltas_m.len() * args.trials;
    let mut done = 0;
    let mut tables = Vec::new();
    for configuration in configurations {
        let setup = TouchSetup {
            count: configuration.touches,
            tip_radius_m: 0.003,
            face_hints: configuration.face_hints,
            approach: true,
        };
        let rows = run_psa_trials(
            &part,
            &setup,
            &configuration.options,
            &deltas_m,
            args.trials,
            args.seed,
            |delta_m, trial| {
                done += 1;
                if trial + 1 == args.trials {
                    progress(&format!(
                        "[{done}/{total}] {} touches, {}: delta {:.0} mm done",
                        configuration.touches,
                        configuration.method,
                        delta_m * 1e3
                    ));
                }
            },
        );
        tables.push(TrialTable {
            touches: configuration.touches,
            face_hints: configuration.face_hints,
            method: configuration.method.to_owned(),
            rows: rows.iter().map(TrialRowJson::from).collect(),
        });
    }
    Ok(TrialsOutput {
        part: part.name,
        trials_per_delta: args.trials,
        seed: args.seed,
        tables,
    })
}

impl TrialsOutput {
    /// Markdown: one table per touch count, the methods side by side per delta.
    pub fn to_markdown(&self) -> String {
        let mut text = format!(
            "{} trials on '{}', {} trials per delta, seed {} (success: final pose within 1 mm, thesis eq. 22)\n",
            if self.tables.iter().all(|t| t.touches == 0) {
                "PCA"
            } else {
                "PSA"
            },
            self.part,
            self.trials_per_delta,
            self.seed
        );
        let mut counts: Vec<usize> = self.tables.iter().map(|t| t.touches).collect();
        counts.dedup();
        for touches in counts {
            let tables: Vec<&TrialTable> = self
                .tables
                .iter()
                .filter(|t| t.touches == touches)
                .collect();
            let title = if touches == 0 {
                "Point Cloud Alignment".to_owned()
            } else {
                format!("{touches} touches")
            };
            text += &format!("\n### {title}\n\n| Delta (mm) |");
            for table in &tables {
                text += &format!(
                    " {m}: succeed | {m}: fail | {m}: ambiguous | {m}: avg it. | {m}: avg error (mm) | {m}: avg time (s) |",
                    m = table.method
                );
            }
            text += "\n|---:|";
            text += &"---:|".repeat(6 * tables.len());
            text += "\n";
            for (index, row) in tables[0].rows.iter().enumerate() {
                text += &format!("| {:.0} |", row.delta_mm);
                for table in &tables {
                    let row = &table.rows[index];
                    text += &format!(
                        " {} | {} | {} | {:.1} | {:.3e} | {:.2e} |",
                        row.succeeded,
                        row.failed,
                        row.ambiguous,
                        row.mean_iterations,
                        row.mean_error_mm,
                        row.mean_time_s
                    );
                }
                text += "\n";
            }
        }
        text
    }
}
