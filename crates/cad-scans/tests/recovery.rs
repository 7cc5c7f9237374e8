//! ips on scans of real CAD (the meshes shipped in `meshes/`, xArm7 and SO-ARM100 links) at each
//! of the deltas: three seeded scenes per delta, the parts taken in turn, exactly as the
//! `cad-scans` runner makes them (`cad-scans --no-abb --scans 3 --seed 20 --no-peers` prints the
//! same trials). The counts asserted are what ips achieved when the test was written; they are
//! a floor for regressions, not a target (last raised 2026-12-06, to 3/3 at every delta); see
//! docs/cad-scan-trials.md.
//!
//! The scenes changed on 2026-11-27 (fifth session), when the corpus's seeds were mixed
//! properly (`trial_seed`: 40 of seed 20's 200 scans were seed 31's under other numbers). The
//! floors at 100, 500 and 1000 mm were measured again on the new scenes, with the full alignment
//! as it was (that session's changes reach only the local stage); the comments below say what
//! the old scenes gave.
#![allow(clippy::unwrap_used)] // Tests: a panic is the failure report.

use std::path::PathBuf;
use std::sync::OnceLock;

use cad_scans::scanner::ScanNoise;
use cad_scans::scenes::shipped_parts;
use cad_scans::trials::{CorpusOptions, Outcome, Trial, prepare_trials, run_ips};

const DELTAS_MM: [f64; 5] = [50.0, 100.0, 200.0, 500.0, 1000.0];

/// The runner's corpus with its defaults' seed, three scans per delta: made once per test binary.
fn corpus() -> &'static [Trial] {
    static TRIALS: OnceLock<Vec<Trial>> = OnceLock::new();
    TRIALS.get_or_init(|| {
        let options = CorpusOptions {
            deltas_m: DELTAS_MM.iter().map(|d| d * 1e-3).collect(),
            scans_per_delta: 3,
            seed: 20,
            noise: ScanNoise::default(),
            out_dir: PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("cad-scans-recovery"),
        };
        prepare_trials(&shipped_parts().unwrap(), &options, |_, _| {}).unwrap()
    })
}

fn trials_at(delta_mm: f64) -> Vec<(Trial, Outcome)> {
    corpus()
        .iter()
        .filter(|t| (t.delta_m * 1e3 - delta_mm).abs() < 1e-9)
        .map(|trial| (trial.clone(), run_ips(trial, false)))
        .collect()
}

fn successes(results: &[(Trial, Outcome)]) -> usize {
    results.iter().filter(|(t, o)| o.succeeded(t)).count()
}

fn describe(results: &[(Trial, Outcome)]) -> String {
    results
        .iter()
        .map(|(t, o)| {
            format!(
                "{} {:?}: {:.2} mm{}{}",
                t.part,
                t.posture,
                o.error_m(t) * 1e3,
                if o.ambiguous { " ambiguous" } else { "" },
                o.refused
                    .as_deref()
                    .map_or(String::new(), |r| format!(" refused: {r}"))
            )
        })
        .collect::<Vec<_>>()
        .join("; ")
}

#[test]
fn at_50_mm_every_scan_is_recovered_and_none_is_called_ambiguous() {
    let results = trials_at(50.0);
    assert_eq!(successes(&results), 3, "{}", describe(&results));
    // The counterpart of the cylinder's test (refusals.rs): a part that is not symmetric is
    // not reported ambiguous once found.
    assert!(
        results.iter().all(|(_, o)| !o.ambiguous),
        "{}",
        describe(&results)
    );
}

#[test]
fn at_100_mm_every_scan_is_recovered() {
    // Measured 2026-12-06: the xArm7 link4 and base and the SO-ARM100 upper arm, lying, all
    // within 0.25 mm (the base and the arm flagged ambiguous). 3/3 before that session's change
    // too: the floor of 2 written on 2026-11-27 had not been raised since.
    let results = trials_at(100.0);
    assert_eq!(successes(&results), 3, "{}", describe(&results));
    assert_no_confident_wrong_pose(&results, 0.002);
}

#[test]
fn at_200_mm_every_scan_is_recovered() {
    // Measured 2026-12-06: the xArm7 base, the SO-ARM100 upper arm standing and lower arm
    // standing, all within 0.2 mm (each flagged ambiguous). Before the detection without the
    // large planes (docs/cad-scan-trials.md, forty-fourth session) the upper arm ended 128 mm
    // off: 2/3.
    let results = trials_at(200.0);
    assert_eq!(successes(&results), 3, "{}", describe(&results));
    assert_no_confident_wrong_pose(&results, 0.002);
}

/// Every scan is recovered, lands within `near_m`, or is reported ambiguous or refused.
fn assert_no_confident_wrong_pose(results: &[(Trial, Outcome)], near_m: f64) {
    for (trial, outcome) in results {
        let flagged = outcome.ambiguous || outcome.refused.is_some();
        assert!(
            outcome.error_m(trial) < near_m || flagged,
            "a confident wrong pose: {}",
            describe(std::slice::from_ref(&(trial.clone(), outcome.clone())))
        );
    }
}

// 500 and 1000 mm: 2-13 s a scan in the test profile since the exploration's far queries are
// approximate (35-120 s before).
#[test]
fn at_500_mm_every_scan_is_recovered() {
    // Measured 2026-12-06: the SO-ARM100 upper arm standing and lower arm lying, within 0.25 mm
    // (both flagged ambiguous), and the xArm7 link2 lying, 0.04 mm. 3/3 before that session's
    // change too (the floor of 1 was written on 2026-11-27).
    let results = trials_at(500.0);
    assert_eq!(successes(&results), 3, "{}", describe(&results));
    assert_no_confident_wrong_pose(&results, 0.002);
}

#[test]
fn at_1000_mm_every_scan_is_recovered_and_none_refused() {
    // Measured 2026-12-06: the SO-ARM100 lower arm standing (flagged ambiguous), the xArm7 link2
    // and link4, all within 0.15 mm; 3/3 before that session's change too (the floor of 1 was
    // written on 2026-11-27). One of the scenes before the seeds were mixed had an arm's start
    // 0.5 m below the floor, where every scan point near it is nearest to one of its edges, and
    // ips used to refuse it ("only 1 cloud points lie within delta"): the check counts those
    // points, and no scan is refused.
    let results = trials_at(1000.0);
    assert!(
        results.iter().all(|(_, o)| o.refused.is_none()),
        "{}",
        describe(&results)
    );
    assert_eq!(successes(&results), 3, "{}", describe(&results));
}
