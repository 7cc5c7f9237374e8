//! The corpus: seeded scenes of the parts, each with a start displaced by the thesis's scheme
//! (`align_core::trials::random_displacement`, eq. 27-31), written to files; ips aligns each as
//! `ips align-cloud` does (`align_service::jobs::cloud::align`, the service's defaults), and
//! every method's pose is scored by the thesis's pose distance (eq. 22) against the truth.

use std::path::{Path, PathBuf};

use align_core::geometry::Mesh;
use align_core::io::{read_cloud, read_mesh};
use align_core::registration::convergence::pose_distance;
use align_core::registration::pca::{PcaOptions, scan_consensus};
use align_core::trials::{
    SUCCESS_THRESHOLD_M, TrialRng, displace_about_centroid, random_displacement,
};
use align_service::jobs::cloud::{CloudAlignment, align, cloud_options};
use nalgebra::Isometry3;

use crate::files::{SceneFile, TrialFiles, WriteError, isometry_from_rows, write_trial};
use crate::scanner::{Origin, ScanNoise, Surface};
use crate::scenes::{Part, Posture, make_scene};

#[derive(Debug, Clone, PartialEq)]
pub struct CorpusOptions {
    pub deltas_m: Vec<f64>,
    pub scans_per_delta: usize,
    pub seed: u64,
    pub noise: ScanNoise,
    /// Each trial's files go to `out_dir/trial-NNNN/`.
    pub out_dir: PathBuf,
}

/// One scan with its start, written to files.
#[derive(Debug, Clone)]
pub struct Trial {
    pub id: usize,
    pub part: String,
    pub posture: Posture,
    pub delta_m: f64,
    pub world_from_part: Isometry3<f64>,
    pub start: Isometry3<f64>,
    /// The pose distance's radius: the part's, as the project's trials use it.
    pub radius_m: f64,
    pub cloud_points: usize,
    pub part_points: usize,
    pub files: TrialFiles,
}

#[derive(Debug, thiserror::Error)]
pub enum CorpusError {
    #[error("no parts to scan")]
    NoParts,
    #[error("scene {id} ({part}): {source}")]
    Scene {
        id: usize,
        part: String,
        source: crate::SceneError,
    },
    #[error(transparent)]
    Write(#[from] WriteError),
}

/// A seed for trial `index` at delta number `delta_index`: every trial its own scene.
///
/// The run's seed, the delta and the index go through the generator one after the other: when
/// they were XOR-ed together first, scan `i` of seed 20 was scan `i ^ 11` of seed 31 (the same
/// scene whenever the part matched: 40 of 200), so a second seed was not an independent corpus.
fn trial_seed(seed: u64, delta_index: usize, index: usize) -> u64 {
    let of_seed = TrialRng::new(seed).next_u64();
    let of_delta = TrialRng::new(of_seed ^ delta_index as u64).next_u64();
    TrialRng::new(of_delta ^ index as u64).next_u64()
}

/// Makes and writes every trial: `scans_per_delta` at each delta, the parts taken in turn.
/// `on_trial(done, total)` reports progress.
pub fn prepare_trials(
    parts: &[Part],
    options: &CorpusOptions,
    mut on_trial: impl FnMut(usize, usize),
) -> Result<Vec<Trial>, CorpusError> {
    if parts.is_empty() {
        return Err(CorpusError::NoParts);
    }
    let total = options.deltas_m.len() * options.scans_per_delta;
    let mut trials = Vec::with_capacity(total);
    for (delta_index, &delta_m) in options.deltas_m.iter().enumerate() {
        for index in 0..options.scans_per_delta {
            let id = trials.len();
            // Offset by the delta so that a few scans per delta still see different parts.
            let part = &parts[(index + delta_index) % parts.len()];
            let seed = trial_seed(options.seed, delta_index, index);
            trials.push(prepare_trial(id, part, seed, delta_m, options)?);
            on_trial(id + 1, total);
        }
    }
    Ok(trials)
}

pub fn prepare_trial(
    id: usize,
    part: &Part,
    seed: u64,
    delta_m: f64,
    options: &CorpusOptions,
) -> Result<Trial, CorpusError> {
    let scene = make_scene(part, seed, &options.noise).map_err(|source| CorpusError::Scene {
        id,
        part: part.name.clone(),
        source,
    })?;
    let radius_m = part.mesh.radius_m();
    let mut rng = TrialRng::new(seed.rotate_left(17) ^ delta_m.to_bits());
    let displacement = random_displacement(&mut rng, delta_m, radius_m);
    let start = displace_about_centroid(&scene.world_from_part, &part.mesh, &displacement);
    let file = SceneFile {
        id,
        part: part.name.clone(),
        cloud: "cloud.ply".to_owned(),
        mesh: "part.stl".to_owned(),
        delta_m,
        start: align_core::pose::matrix_rows(&start),
    };
    let dir = options.out_dir.join(format!("trial-{id:04}"));
    let cloud = scene.cloud();
    let files = write_trial(&dir, &file, &cloud, &part.soup, &scene.world_from_part)?;
    Ok(Trial {
        id,
        part: part.name.clone(),
        posture: scene.posture,
        delta_m,
        world_from_part: scene.world_from_part,
        start,
        radius_m,
        cloud_points: cloud.len(),
        part_points: scene.count(Origin::Surface(Surface::Part)),
        files,
    })
}

/// What one method made of one trial.
#[derive(Debug, Clone, PartialEq)]
pub struct Outcome {
    /// `None` when the method refused or failed (the part then stays at its start).
    pub pose: Option<Isometry3<f64>>,
    pub time_s: f64,
    pub ambiguous: bool,
    pub refused: Option<String>,
    /// ips's misses only: the scan's score for the pose found and for the truth.
    pub miss_scores: Option<MissScores>,
}

/// The exploration's score ([`align_core::registration::pca::scan_consensus`]) of a wrong pose
/// and of the truth: a truth that scores higher was never reached by the search, one that
/// scores lower or the same is a scan the score cannot read.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MissScores {
    pub found: f64,
    pub truth: f64,
}

impl MissScores {
    /// The search's miss when the truth outscores the found pose by more than the scores'
    /// sampling noise (2 sqrt(score), as the uniqueness test uses).
    pub fn search_missed(&self) -> bool {
        self.truth - self.found > 2.0 * self.truth.max(0.0).sqrt()
    }
}

impl Outcome {
    pub fn refused(reason: impl Into<String>) -> Self {
        Self {
            pose: None,
            time_s: 0.0,
            ambiguous: false,
            refused: Some(reason.into()),
            miss_scores: None,
        }
    }

    /// The thesis's pose distance from the truth; a refusal scores its start.
    pub fn error_m(&self, trial: &Trial) -> f64 {
        let pose = self.pose.unwrap_or(trial.start);
        pose_distance(&pose, &trial.world_from_part, trial.radius_m)
    }

    pub fn succeeded(&self, trial: &Trial) -> bool {
        self.error_m(trial) < SUCCESS_THRESHOLD_M
    }
}

/// ips on one trial's files, exactly as `ips align-cloud --cloud C --mesh M --pose P --delta D`
/// runs it (point-to-plane, cos schedule, the exploration on); with `local`, as
/// `ips align-cloud --local` runs it: the local stage alone (the schedule from the start and the
/// polish), the class of method the peers are.
pub fn run_ips(trial: &Trial, local: bool) -> Outcome {
    let job = CloudAlignment {
        cloud: trial.files.cloud.clone(),
        cloud_scale: 1.0,
        mesh: trial.files.mesh.clone(),
        mesh_scale: 1.0,
        base_from_part_start: trial.start,
        delta_m: trial.delta_m,
        options: cloud_options(false, None, local),
    };
    match align(&job) {
        Ok(report) => {
            let pose = &report.alignment.pose;
            let pose = match &pose.matrix {
                Some(rows) => isometry_from_rows(rows),
                None => align_core::pose::isometry_from_xyz_rpy(pose.xyz, pose.rpy),
            };
            let mut outcome = Outcome {
                pose: Some(pose),
                time_s: report.alignment.time_s,
                ambiguous: report.ambiguous,
                refused: None,
                miss_scores: None,
            };
            if !outcome.succeeded(trial) {
                outcome.miss_scores = miss_scores(trial, &pose, &job.options);
            }
            outcome
        }
        Err(error) => Outcome::refused(error.0),
    }
}

/// The scores of a wrong pose and of the truth on the trial's files (after the timed run);
/// `None` when the files no longer read.
fn miss_scores(trial: &Trial, pose: &Isometry3<f64>, options: &PcaOptions) -> Option<MissScores> {
    let soup = read_mesh(&trial.files.mesh, 1.0).ok()?;
    let mesh = Mesh::new(&soup.vertices, &soup.triangles).ok()?;
    let cloud = read_cloud(&trial.files.cloud, 1.0).ok()?;
    Some(MissScores {
        found: scan_consensus(&mesh, &cloud, pose, options),
        truth: scan_consensus(&mesh, &cloud, &trial.world_from_part, options),
    })
}

/// Where the trial's files are, for a manifest.
pub fn scene_json(trial: &Trial) -> PathBuf {
    trial.files.dir.join("scene.json")
}

pub fn write_manifest(path: &Path, trials: &[Trial]) -> std::io::Result<()> {
    let paths: Vec<String> = trials
        .iter()
        .map(|t| scene_json(t).display().to_string())
        .collect();
    let text = serde_json::to_string_pretty(&paths).map_err(std::io::Error::other)?;
    std::fs::write(path, text)
}

#[cfg(test)]
mod tests {
    use super::{MissScores, trial_seed};

    #[test]
    fn two_seeds_share_no_scan() {
        let scans = |seed: u64| -> std::collections::HashSet<u64> {
            (0..5)
                .flat_map(|delta| (0..200).map(move |index| trial_seed(seed, delta, index)))
                .collect()
        };
        let (a, b) = (scans(20), scans(31));
        assert_eq!(a.len(), 1000, "one seed's scans repeat");
        assert_eq!(a.intersection(&b).count(), 0);
    }

    #[test]
    fn a_miss_is_the_searchs_only_when_the_truth_scores_clearly_higher() {
        let search = MissScores {
            found: 300.0,
            truth: 900.0,
        };
        assert!(search.search_missed());
        let score = MissScores {
            found: 320.0,
            truth: 300.0,
        };
        assert!(!score.search_missed());
        // Within the scores' noise (2 sqrt(100) = 20): the score cannot tell them apart.
        let close = MissScores {
            found: 90.0,
            truth: 100.0,
        };
        assert!(!close.search_missed());
    }
}
