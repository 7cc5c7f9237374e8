//! Unit tests of how the beam search goes from one joint's searches to its next states (see
//! [`super::beam::next_states`]).

use nalgebra::Isometry3;

use super::RobotFitOptions;
use super::beam::{keep_best, leaves_windows, next_states};
use super::joint_search::Candidate;

fn candidate(
    value: f64,
    partner: Option<(usize, f64)>,
    deferred: Option<(usize, f64)>,
) -> Candidate {
    Candidate {
        value,
        partner,
        deferred,
        score: 1,
    }
}

/// A state whose search found nothing to score goes on as it was, beside the states the other
/// searches led to; it was dropped, and a right base with it.
#[test]
fn a_state_whose_search_finds_nothing_goes_on_unchanged() {
    let options = RobotFitOptions::default();
    let wrist = 3;
    let beam = vec![
        (
            Isometry3::translation(0.2, -0.1, 0.0),
            vec![0.0, 0.3, 2.9, -0.4, 0.0],
        ),
        (
            Isometry3::translation(0.0, -0.57, 0.0),
            vec![-0.6, 1.1, -1.4, -0.4, 0.0],
        ),
    ];
    let searched = vec![
        Vec::new(),
        vec![
            candidate(0.7, Some((4, 1.5)), None),
            candidate(1.4, None, Some((2, -1.2))),
        ],
    ];
    let next = next_states(&beam, searched, wrist, &options).unwrap();
    assert_eq!(next.len(), 3, "{next:?}");
    assert!(next.contains(&(beam[0].clone(), 0)), "{next:?}");
    // The other state's candidates, their partner's and deferred joint's values set.
    assert!(next.contains(&((beam[1].0, vec![-0.6, 1.1, -1.4, 0.7, 1.5]), 1)));
    assert!(next.contains(&((beam[1].0, vec![-0.6, 1.1, -1.2, 1.4, 0.0]), 1)));
}

/// A state reached twice (by two searches, or unchanged and by a search) is kept once; when no
/// search found anything there are no next states (the joint is left undecided).
#[test]
fn states_reached_twice_are_kept_once_and_no_search_finding_anything_gives_none() {
    let options = RobotFitOptions::default();
    let base = Isometry3::translation(0.2, -0.1, 0.0);
    let beam = vec![(base, vec![0.0, 0.5]), (base, vec![0.0, 0.9])];
    let none = next_states(&beam, vec![Vec::new(), Vec::new()], 1, &options);
    assert!(none.is_none());
    // The second state's search leads to the first state's value; the first found nothing.
    let next = next_states(
        &beam,
        vec![
            Vec::new(),
            vec![candidate(0.5, None, None), candidate(0.5, None, None)],
        ],
        1,
        &options,
    )
    .unwrap();
    assert_eq!(next, vec![((base, vec![0.0, 0.5]), 1)]);
}

/// A refinement that turns a joint farther than its window leaves what the start allows; one
/// that stays within every window, or moves a joint without a placed axis, does not.
#[test]
fn a_joint_turned_past_its_window_leaves_it() {
    let halves = [0.8, 0.3, f64::INFINITY];
    let before = [-0.45, 1.8, 0.2];
    // The ABB's forearm roll turned by 1.9 rad where delta allowed 0.8.
    assert!(leaves_windows(&before, &[-2.35, 1.78, 0.9], &halves));
    assert!(leaves_windows(&before, &[-0.45, 2.2, 0.2], &halves));
    assert!(!leaves_windows(&before, &[0.3, 1.55, 5.0], &halves));
    assert!(!leaves_windows(&before, &before, &halves));
}

/// The first cut keeps each base hypothesis's best state beside the `width` best; later cuts
/// keep the `width` best only. A hypothesis whose best state is another's copy goes on with its
/// next best.
#[test]
fn the_first_cut_keeps_each_hypothesis_s_best_state() {
    let options = RobotFitOptions::default();
    let state = |x: f64, q: f64| (Isometry3::translation(x, 0.0, 0.0), vec![q]);
    let scored = vec![
        (16, state(0.0, 0.1), 2),
        (28, state(0.3, 0.2), 0),
        (25, state(0.3, 0.9), 0),
        (22, state(0.5, 0.4), 1),
        // Hypothesis 3 reached hypothesis 0's best state; its next best is its own.
        (28, state(0.3, 0.2), 3),
        (12, state(0.7, 0.6), 3),
        (14, state(0.0, 0.7), 2),
    ];
    let later = keep_best(scored.clone(), 2, false, &options);
    assert_eq!(later, vec![(state(0.3, 0.2), 0), (state(0.3, 0.9), 0)]);
    let first = keep_best(scored, 2, true, &options);
    assert_eq!(
        first,
        vec![
            (state(0.3, 0.2), 0),
            (state(0.3, 0.9), 0),
            (state(0.5, 0.4), 1),
            (state(0.0, 0.1), 2),
            (state(0.7, 0.6), 3),
        ]
    );
}
