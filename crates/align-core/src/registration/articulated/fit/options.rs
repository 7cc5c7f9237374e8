//! The fit's options.

use crate::registration::pca::{DeltaSchedule, PcaOptions};
use crate::registration::ppf::PpfOptions;

#[derive(Debug, Clone, PartialEq)]
pub struct RobotFitOptions {
    /// Voxel edge of the keypoints, m.
    pub voxel_m: f64,
    /// The band the refinement ends with: points farther from every link are not used, m.
    pub band_min_m: f64,
    /// A link with fewer points than this is reported as not visible; a twin or a flip must
    /// explain this many keypoints more to replace the fit.
    pub min_link_points: usize,
    /// A joint whose motion moves its points along their normals by less than this fraction of
    /// its reach per radian (RMS) is not constrained by the scan.
    pub min_observability: f64,
    /// A joint is observed only when the scan pins it to within this at its reach (one
    /// standard deviation, from the points' residuals, without the few points that carry most
    /// of its evidence: see `observed_parameters`), m: half the millimetre the trials call
    /// success.
    pub observed_within_m: f64,
    pub search_passes: usize,
    /// States the first search down the tree keeps at each joint.
    pub beam_width: usize,
    /// `beam_width` and `search_passes` when the start is near: delta at most 0.18 of the
    /// robot's radius at the start joints, where the searches from the start settle every
    /// joint in its basin (see `align_robot`).
    pub near_beam_width: usize,
    pub near_search_passes: usize,
    /// Further base poses the search starts from when the start may be off by about as much as
    /// the base is big: rigid alignments of the base and the links only the first joint moves
    /// (0: none, detected ones included).
    pub base_candidates: usize,
    /// Base poses the detection of the proximal links gives when the start is not local (delta
    /// beyond the robot's radius). Point pair features can rank the true place of a boxy base
    /// below others: the proximal links are detected at the start's value of the first joint,
    /// and where that is far off only the base's features vote for the truth. On the ABB IRB
    /// 1600 at 1000 mm the pose nearest the truth ranked 6th to 29th in the four trials of 50
    /// that fewer lost (14 and 16 with 4 poses, 17 and 21 with 12; docs/articulated-trials.md).
    pub detected_bases: usize,
    /// Scan points whose voxel (`voxel_m`) has fewer occupied voxels than this within two
    /// voxels of it are left out before anything else ([`without_isolated`]: a scanner's
    /// spurious returns and mixed pixels); 0 keeps every point.
    ///
    /// [`without_isolated`]: crate::registration::sampling::without_isolated
    pub isolated_min_neighbours: usize,
    /// Sweep the joints of the small links at the end of the chain (a wrist and its flange)
    /// densely in a narrow band after the last refinement (`FitContext::distal_sweep`).
    pub distal_sweep: bool,
    /// The band of one more exact refinement after everything else, m (0: none): a few times
    /// the scan's noise, so that the mixed pixels beside a small link's silhouette no longer
    /// pull it.
    pub polish_band_m: f64,
    pub max_iterations: usize,
    /// The refinement stops when a step moves the points along their normals by less than this
    /// (RMS), m.
    pub tolerance_m: f64,
    pub parallel: bool,
    /// The rigid first alignment of the whole robot.
    pub base: PcaOptions,
    /// The exploration and the spread of starts for rigid alignments of the proximal links
    /// (`base_candidates` from each).
    pub proximal: PcaOptions,
    /// The detection of the proximal links anywhere near the start (point pair features),
    /// which gives the base candidates instead when the start is not local (delta beyond the
    /// robot's radius).
    pub detection: PpfOptions,
}

impl Default for RobotFitOptions {
    fn default() -> Self {
        Self {
            voxel_m: 0.006,
            band_min_m: 0.01,
            min_link_points: 12,
            min_observability: 0.05,
            observed_within_m: 0.0005,
            search_passes: 2,
            beam_width: 6,
            // About a third of a 100 mm fit's instructions less (`articulated_starts`, callgrind)
            // with every link 50/50 at 50 and 100 mm (docs/articulated-trials.md).
            near_beam_width: 3,
            near_search_passes: 1,
            base_candidates: 4,
            detected_bases: 40,
            isolated_min_neighbours: 3,
            distal_sweep: true,
            polish_band_m: 0.005,
            // The last refinement starts within the narrow band and takes a handful when the
            // correspondences settle; should they cycle (points switching between links at the
            // 0.1 mm level), it keeps the best of 25.
            max_iterations: 25,
            // A tenth of a millimetre: a tenth of the success bar, below the scan's noise.
            tolerance_m: 1e-4,
            parallel: true,
            // 20 mm keypoints, a short schedule and a loose stop (half a millimetre over five
            // iterations): the rigid stage only has to bring the base near; the joints are
            // still wrong while it runs, so it cannot converge closer than that and would only
            // run to its limit. (30 mm keypoints lost an iiwa14 at 100 mm in exploratory runs.)
            base: PcaOptions {
                voxel_m: 0.02,
                schedule_iterations: 40,
                max_iterations: 60,
                tolerance_m: 5e-4,
                window: 5,
                // The robot trials (docs/articulated-trials.md) were measured without it.
                wide_exploration: false,
                // Bringing the base near is all this stage is for; the joint refinement ends it.
                polish: false,
                // A ray-cast scan's floor reaches metres around the robot: with it, 5 of 50
                // fits at 200 mm lost the base 0.1-0.4 m off when the isolated returns were
                // kept too (crates/cad-scans, `robot-scans`; docs/articulated-trials.md).
                without_large_planes: true,
                // The fit's half-turn check and second look tell the robot's twins apart; the
                // runs about the found pose were a third of a 100 mm fit's rigid stage
                // (docs/BENCHMARKS.md) and changed no fit of the bench's 40.
                twin_search: false,
                // The robot trials were measured without it; the robot's start is not a
                // part's, and its joints are still wrong here.
                local_candidate: false,
                // The robot trials were measured with the cosine schedule (eq. 33).
                schedule: DeltaSchedule::Cosine,
                // The robot trials were measured with every keypoint in the band counted.
                oriented_score: false,
                ..PcaOptions::default()
            },
            // The proximal links are small: 15 mm keypoints (45 mm for the exploration's and the
            // spread's runs, 45-90 mm for the spread's screening).
            proximal: PcaOptions {
                voxel_m: 0.015,
                schedule_iterations: 40,
                max_iterations: 60,
                // As measured for docs/articulated-trials.md (the window then the default).
                polish: false,
                window: 19,
                without_large_planes: false,
                schedule: DeltaSchedule::Cosine,
                // The robot trials were measured with every keypoint in the band counted.
                oriented_score: false,
                ..PcaOptions::default()
            },
            // Every reference's vote is merged: the true base of a cluttered scan is a pose many
            // references agree on, each with few votes of its own. With votes under a fifth of
            // the best reference's dropped before merging (the default), the ABB IRB 1600's
            // true base was among none of the 117 poses left in `robot-scans --seed 91` scene 0
            // at 1000 mm; with every vote merged it ranks 6th of 737, and the fit finds it in
            // 10 of 10 trials there (2 before). Merging a thousand more votes costs little
            // beside the voting.
            detection: PpfOptions {
                min_vote_fraction: 0.0,
                ..PpfOptions::default()
            },
        }
    }
}

impl RobotFitOptions {
    /// The band a refinement starts from, before it shrinks to `band_min_m`.
    pub(super) fn refine_band0_m(&self) -> f64 {
        (3.0 * self.band_min_m).max(self.voxel_m * 6.0)
    }
}
