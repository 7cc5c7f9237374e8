//! The one table of a run: successes per delta for ips and each peer, and median times; the
//! same numbers as JSON.

use serde::Serialize;

use crate::trials::{Outcome, Trial};

/// The methods in the table's column order: ips first, then ips's local stage alone (when
/// asked for), then the peers that ran.
pub const IPS: &str = "ips";
pub const IPS_LOCAL: &str = "ips_local";

/// One trial's outcome per method, in `methods` order (`None`: the method did not run).
#[derive(Debug, Clone)]
pub struct Scored<'a> {
    pub trial: &'a Trial,
    pub outcomes: Vec<Option<Outcome>>,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MethodCell {
    pub method: String,
    pub succeeded: usize,
    pub trials: usize,
    /// Trials the method reported ambiguous (ips only; counted by their pose too).
    pub ambiguous: usize,
    pub refused: usize,
    /// Misses whose truth outscores the pose found: the search never reached it (ips only).
    pub search_misses: usize,
    /// Misses whose pose scores as well as the truth or better: the score cannot tell (ips
    /// only).
    pub score_misses: usize,
    pub median_error_mm: f64,
    pub median_time_s: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Row {
    /// `None` for the row over all deltas.
    pub delta_mm: Option<f64>,
    pub cells: Vec<MethodCell>,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TrialRecord {
    pub id: usize,
    pub part: String,
    pub posture: String,
    pub delta_mm: f64,
    pub cloud_points: usize,
    pub part_points: usize,
    pub methods: Vec<MethodRecord>,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MethodRecord {
    pub method: String,
    pub error_mm: f64,
    pub succeeded: bool,
    pub time_s: f64,
    pub ambiguous: bool,
    pub refused: Option<String>,
    /// ips's misses: the exploration's score of the pose found and of the truth.
    pub found_score: Option<f64>,
    pub truth_score: Option<f64>,
}

pub fn records(scored: &[Scored], methods: &[String]) -> Vec<TrialRecord> {
    scored
        .iter()
        .map(|s| TrialRecord {
            id: s.trial.id,
            part: s.trial.part.clone(),
            posture: format!("{:?}", s.trial.posture).to_lowercase(),
            delta_mm: s.trial.delta_m * 1e3,
            cloud_points: s.trial.cloud_points,
            part_points: s.trial.part_points,
            methods: methods
                .iter()
                .zip(&s.outcomes)
                .filter_map(|(method, outcome)| {
                    let outcome = outcome.as_ref()?;
                    Some(MethodRecord {
                        method: method.clone(),
                        error_mm: outcome.error_m(s.trial) * 1e3,
                        succeeded: outcome.succeeded(s.trial),
                        time_s: outcome.time_s,
                        ambiguous: outcome.ambiguous,
                        refused: outcome.refused.clone(),
                        found_score: outcome.miss_scores.map(|m| m.found),
                        truth_score: outcome.miss_scores.map(|m| m.truth),
                    })
                })
                .collect(),
        })
        .collect()
}

/// A row per delta (in the order they first appear) and one over all.
pub fn rows(scored: &[Scored], methods: &[String]) -> Vec<Row> {
    let mut deltas: Vec<f64> = Vec::new();
    for s in scored {
        if !deltas.contains(&s.trial.delta_m) {
            deltas.push(s.trial.delta_m);
        }
    }
    let mut rows: Vec<Row> = deltas
        .iter()
        .map(|&delta_m| {
            let at: Vec<&Scored> = scored
                .iter()
                .filter(|s| s.trial.delta_m == delta_m)
                .collect();
            Row {
                delta_mm: Some(delta_m * 1e3),
                cells: cells(&at, methods),
            }
        })
        .collect();
    let all: Vec<&Scored> = scored.iter().collect();
    rows.push(Row {
        delta_mm: None,
        cells: cells(&all, methods),
    });
    rows
}

fn cells(scored: &[&Scored], methods: &[String]) -> Vec<MethodCell> {
    methods
        .iter()
        .enumerate()
        .map(|(index, method)| {
            let ran: Vec<(&Trial, &Outcome)> = scored
                .iter()
                .filter_map(|s| Some((s.trial, s.outcomes.get(index)?.as_ref()?)))
                .collect();
            let mut errors: Vec<f64> = ran.iter().map(|(t, o)| o.error_m(t) * 1e3).collect();
            let mut times: Vec<f64> = ran.iter().map(|(_, o)| o.time_s).collect();
            MethodCell {
                method: method.clone(),
                succeeded: ran.iter().filter(|(t, o)| o.succeeded(t)).count(),
                trials: ran.len(),
                ambiguous: ran.iter().filter(|(_, o)| o.ambiguous).count(),
                refused: ran.iter().filter(|(_, o)| o.refused.is_some()).count(),
                search_misses: ran
                    .iter()
                    .filter(|(_, o)| o.miss_scores.is_some_and(|m| m.search_missed()))
                    .count(),
                score_misses: ran
                    .iter()
                    .filter(|(_, o)| o.miss_scores.is_some_and(|m| !m.search_missed()))
                    .count(),
                median_error_mm: median(&mut errors),
                median_time_s: median(&mut times),
            }
        })
        .collect()
}

/// The median (the mean of the middle two for an even count); NaN for none.
pub fn median(values: &mut [f64]) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    values.sort_by(f64::total_cmp);
    let middle = values.len() / 2;
    if values.len() % 2 == 1 {
        values[middle]
    } else {
        0.5 * (values[middle - 1] + values[middle])
    }
}

fn column_title(method: &str) -> &str {
    match method {
        "open3d" => "Open3D point-to-plane, coarse-to-fine, Tukey",
        "small_gicp" => "small_gicp GICP, coarse-to-fine",
        IPS_LOCAL => "ips local stage only (--local)",
        other => other,
    }
}

/// The Markdown table: successes (pose distance < 1 mm) per delta, ambiguous and refused counts
/// in brackets where there are any, then the median pose errors and times.
pub fn markdown(rows: &[Row]) -> String {
    let Some(first) = rows.first() else {
        return String::new();
    };
    let titles: Vec<&str> = first
        .cells
        .iter()
        .map(|c| column_title(&c.method))
        .collect();
    let mut text = format!("| delta (mm) | {} |\n", titles.join(" | "));
    text += &format!("|---|{}\n", "---|".repeat(titles.len()));
    for row in rows {
        let delta = row
            .delta_mm
            .map_or_else(|| "all".to_owned(), |d| format!("{d:.0}"));
        let cells: Vec<String> = row.cells.iter().map(success_cell).collect();
        text += &format!("| {delta} | {} |\n", cells.join(" | "));
    }
    if let Some(all) = rows.last() {
        let errors: Vec<String> = all
            .cells
            .iter()
            .map(|c| format!("{:.2} mm", c.median_error_mm))
            .collect();
        let times: Vec<String> = all
            .cells
            .iter()
            .map(|c| format!("{:.3} s", c.median_time_s))
            .collect();
        text += &format!("| median pose error | {} |\n", errors.join(" | "));
        text += &format!("| median time | {} |\n", times.join(" | "));
        for cell in all
            .cells
            .iter()
            .filter(|c| c.search_misses + c.score_misses > 0)
        {
            text += &format!(
                "\n{}'s misses: {} where the truth scores higher (the search never reached it), \
                 {} where the pose found scores as well or better (the score cannot tell).\n",
                cell.method, cell.search_misses, cell.score_misses
            );
        }
    }
    text
}

fn success_cell(cell: &MethodCell) -> String {
    let mut text = format!("{}/{}", cell.succeeded, cell.trials);
    let mut notes = Vec::new();
    if cell.ambiguous > 0 {
        notes.push(format!("{} ambiguous", cell.ambiguous));
    }
    if cell.refused > 0 {
        notes.push(format!("{} refused", cell.refused));
    }
    if !notes.is_empty() {
        text += &format!(" ({})", notes.join(", "));
    }
    text
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_median_of_an_even_count_is_the_mean_of_the_middle_two() {
        assert_eq!(super::median(&mut [4.0, 1.0, 3.0, 2.0]), 2.5);
        assert_eq!(super::median(&mut [5.0, 1.0, 3.0]), 3.0);
        assert!(super::median(&mut []).is_nan());
    }
}
