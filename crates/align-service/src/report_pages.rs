//! The diagnosis as pictures, drawn from the report document alone so that every place showing
//! one shows the same: `ips diagnose SESSION` writes [`diagnosis_svg`] and [`diagnosis_page`]
//! next to the session, and the operator page (`ips serve --http`) shows [`diagnosis_section`]
//! for the service's latest `diagnose`.
//!
//! Everything taken from the report (inspection ids, effect and candidate names, the
//! explanation) is escaped: a session file may name its inspections anything.

use std::fmt::Write as _;

use align_core::io::export::xml_escaped as escaped;
use protocol::reports::DiagnoseReport;

use crate::jobs::units::person_unit;

/// Height of the scatter panel under the bars, px.
const SCATTER_HEIGHT_PX: f64 = 320.0;
/// Smallest drawn bar, px: a bar thinner than a pixel reads as a missing one.
const MIN_BAR_PX: f64 = 2.0;
/// Height of the bar panel, px.
const BARS_HEIGHT_PX: f64 = 340.0;
/// Margin around the bar panel's band, px.
const MARGIN_PX: f64 = 50.0;

fn mm(value_m: f64) -> String {
    format!("{:.4}", value_m * 1e3 + 0.0)
}

/// The effect the diagnosis applied: its best candidate only when the verdict is `effect` (an
/// ambiguous or unattributable verdict names a candidate but applies nothing).
fn applied_effect(report: &DiagnoseReport) -> Option<&str> {
    report
        .effect
        .as_ref()
        .filter(|_| report.verdict == "effect")
        .map(|effect| effect.name.as_str())
}

/// Residual per touch, before (grey) and after (blue), with the +-2 sigma band of the declared
/// noise; below, when an effect was applied, each touch's residual against what the effect
/// explains of it (on the diagonal when the effect accounts for the residual).
pub fn diagnosis_svg(report: &DiagnoseReport) -> String {
    let applied = applied_effect(report);
    let touches = &report.inspections;
    let sigma = report.noise_sigma_m.unwrap_or(0.0);
    let titles = [
        if report.noise_sigma_m.is_some() {
            "Residual per touch (mm): before (grey), after (blue); green band = +-2 sigma"
        } else {
            "Residual per touch (mm): before (grey), after (blue)"
        }
        .to_owned(),
        match (applied, &report.effect) {
            (Some(name), _) => format!("Verdict: {}; after = modelling {name}", report.verdict),
            (None, Some(best)) => format!(
                "Verdict: {}; nothing applied (best candidate {}): after = before",
                report.verdict, best.name
            ),
            (None, None) => format!(
                "Verdict: {}; nothing applied: after = before",
                report.verdict
            ),
        },
    ];
    // Wide enough for the longest title (about 7 px per character at 12 px sans-serif).
    let longest_title = titles.iter().map(|t| t.chars().count()).max().unwrap_or(0);
    let width = (80.0 + 40.0 * touches.len() as f64)
        .max(2.0 * SCATTER_HEIGHT_PX)
        .max(20.0 + 7.0 * longest_title as f64);
    let (height, margin) = (BARS_HEIGHT_PX, MARGIN_PX);
    let largest = touches
        .iter()
        .flat_map(|t| [t.residual_before, t.residual_after])
        .filter(|r| r.is_finite())
        .fold(3.0 * sigma, |m, r| m.max(r.abs()))
        .max(1e-9);
    let y = |value: f64| height / 2.0 - value / largest * (height / 2.0 - margin);
    let total_height = height
        + if applied.is_some() {
            SCATTER_HEIGHT_PX
        } else {
            50.0
        };
    let mut out = format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" viewBox=\"0 0 {width:.0} {total_height:.0}\" width=\"{width:.0}\" height=\"{total_height:.0}\" font-family=\"sans-serif\" font-size=\"12\">\n\
         <rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n\
         <text x=\"10\" y=\"18\">{}</text>\n\
         <text x=\"10\" y=\"34\">{}</text>\n",
        escaped(&titles[0]),
        escaped(&titles[1]),
    );
    if sigma > 0.0 {
        let _ = writeln!(
            out,
            "<rect x=\"{margin}\" y=\"{:.1}\" width=\"{:.1}\" height=\"{:.1}\" fill=\"#e8f0e8\"/>",
            y(2.0 * sigma),
            width - 2.0 * margin,
            y(-2.0 * sigma) - y(2.0 * sigma),
        );
    }
    let _ = writeln!(
        out,
        "<line x1=\"{margin}\" y1=\"{:.1}\" x2=\"{:.1}\" y2=\"{:.1}\" stroke=\"black\"/>",
        y(0.0),
        width - margin,
        y(0.0)
    );
    for (i, touch) in touches.iter().enumerate() {
        let x = margin + 20.0 + 40.0 * i as f64;
        let id = escaped(&touch.id);
        for (offset, value, colour) in [
            (-6.0, touch.residual_before, "#999"),
            (6.0, touch.residual_after, "#2a6fdb"),
        ] {
            let (mut top, mut bottom) = if value >= 0.0 {
                (y(value), y(0.0))
            } else {
                (y(0.0), y(value))
            };
            if (bottom - top).is_nan() || bottom - top < MIN_BAR_PX {
                let middle = (top + bottom) / 2.0;
                let middle = if middle.is_finite() { middle } else { y(0.0) };
                (top, bottom) = (middle - MIN_BAR_PX / 2.0, middle + MIN_BAR_PX / 2.0);
            }
            let shown = if value.is_finite() {
                format!("{:+.4} mm", value * 1e3)
            } else {
                "not computed".to_owned()
            };
            let _ = writeln!(
                out,
                "<rect x=\"{:.1}\" y=\"{top:.1}\" width=\"10\" height=\"{:.1}\" fill=\"{colour}\"><title>{id} {shown}</title></rect>",
                x + offset - 5.0,
                bottom - top,
            );
        }
        let _ = writeln!(
            out,
            "<text x=\"{x:.1}\" y=\"{:.1}\" text-anchor=\"middle\">{id}</text>",
            height - 10.0,
        );
    }
    let _ = writeln!(
        out,
        "<text x=\"5\" y=\"{:.1}\">{:+.3}</text>\n<text x=\"5\" y=\"{:.1}\">{:+.3}</text>",
        y(largest) + 4.0,
        largest * 1e3,
        y(-largest) + 4.0,
        -largest * 1e3
    );
    out += &scatter(report, applied, largest, height);
    out += "</svg>\n";
    out
}

/// The lower panel: residual before (y) against the part the effect explains (x), both mm.
fn scatter(report: &DiagnoseReport, applied: Option<&str>, largest: f64, top: f64) -> String {
    let Some(name) = applied else {
        return format!(
            "<text x=\"10\" y=\"{:.1}\">No effect applied (verdict {}): nothing to plot against.</text>\n",
            top + 30.0,
            escaped(&report.verdict)
        );
    };
    let (left, size) = (60.0, SCATTER_HEIGHT_PX - 60.0);
    let to_px = |value: f64| size / 2.0 * (1.0 - value / largest);
    let mut out = format!(
        "<text x=\"10\" y=\"{:.1}\">Residual before (y) against what {} explains of it (x), mm; on the diagonal = explained</text>\n\
         <rect x=\"{left}\" y=\"{:.1}\" width=\"{size}\" height=\"{size}\" fill=\"none\" stroke=\"#ccc\"/>\n\
         <line x1=\"{left}\" y1=\"{:.1}\" x2=\"{:.1}\" y2=\"{:.1}\" stroke=\"#2a6fdb\" stroke-dasharray=\"4 3\"/>\n",
        top + 20.0,
        escaped(name),
        top + 40.0,
        top + 40.0 + size,
        left + size,
        top + 40.0
    );
    for touch in &report.inspections {
        let before = touch.residual_before;
        let explained = before - touch.residual_after;
        if !(before.is_finite() && explained.is_finite()) {
            continue;
        }
        let _ = writeln!(
            out,
            "<circle cx=\"{:.1}\" cy=\"{:.1}\" r=\"4\" fill=\"#444\"><title>{} explained {:+.4} of {:+.4} mm</title></circle>",
            left + size - to_px(explained),
            top + 40.0 + to_px(before),
            escaped(&touch.id),
            explained * 1e3,
            before * 1e3
        );
    }
    let _ = writeln!(
        out,
        "<text x=\"{left}\" y=\"{:.1}\">{:+.3}</text><text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"end\">{:+.3}</text>",
        top + 55.0 + size,
        -largest * 1e3,
        left + size,
        top + 55.0 + size,
        largest * 1e3
    );
    out
}

/// The diagnosis as HTML without a page around it: the verdict, the effect with its error in
/// the units people read, rms / max / leave-one-out before and after, the residual plot
/// (inline SVG), every candidate that lost and why, and the touches. Headings start at `h2`.
pub fn diagnosis_section(report: &DiagnoseReport) -> String {
    let mut html = format!(
        "<p class=\"verdict\">Verdict: <strong id=\"verdict\">{}</strong></p>\n<p>{}</p>\n",
        escaped(&report.verdict),
        escaped(&report.explanation),
    );
    match (&report.effect, applied_effect(report)) {
        (Some(effect), Some(_)) => {
            let _ = write!(
                html,
                "<h2>Applied: {}</h2>\n<table><tr><th>parameter</th><th>value</th><th>standard error</th></tr>\n",
                escaped(&effect.name)
            );
            for (name, value) in &effect.params {
                let (factor, unit, decimals) = person_unit(name);
                let stderr = effect.stderr.get(name).copied().unwrap_or(f64::NAN);
                let _ = writeln!(
                    html,
                    "<tr><td>{}</td><td class=\"n\">{:+.decimals$} {unit}</td><td class=\"n\">{:.decimals$} {unit}</td></tr>",
                    escaped(name),
                    value * factor,
                    stderr * factor
                );
            }
            html += "</table>\n";
        }
        (Some(effect), None) => {
            let _ = writeln!(
                html,
                "<h2>Nothing applied</h2>\n<p>The best candidate, {}, is not applied: see the verdict.</p>",
                escaped(&effect.name)
            );
        }
        (None, _) => html += "<h2>Nothing applied</h2>\n",
    }
    let (before, after) = (&report.before, &report.after);
    let _ = write!(
        html,
        "<table><tr><th></th><th>rms (mm)</th><th>max (mm)</th><th>leave-one-out rms (mm)</th></tr>\n\
         <tr><td>before</td><td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td></tr>\n\
         <tr><td>after</td><td class=\"n\">{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td></tr></table>\n",
        mm(before.rms),
        mm(before.max),
        mm(before.loo_rms),
        mm(after.rms),
        mm(after.max),
        mm(after.loo_rms)
    );
    let _ = write!(
        html,
        "<h2>Residuals</h2>\n<figure>{}</figure>\n",
        diagnosis_svg(report)
    );
    html += "<h2>Candidates not chosen</h2>\n<table id=\"alternatives\"><tr><th>candidate</th><th>BIC</th><th>leave-one-out rms (mm)</th><th>why</th></tr>\n";
    for alternative in &report.alternatives {
        let _ = writeln!(
            html,
            "<tr><td>{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td><td>{}</td></tr>",
            escaped(&alternative.name),
            alternative
                .bic
                .map_or("-".to_owned(), |b| format!("{b:.1}")),
            alternative.loo_rms.map_or("-".to_owned(), mm),
            escaped(&alternative.reason)
        );
    }
    html += "</table>\n<h2>Touches</h2>\n<table id=\"touches\"><tr><th>touch</th><th>residual before (mm)</th><th>after (mm)</th></tr>\n";
    for touch in &report.inspections {
        let _ = writeln!(
            html,
            "<tr><td>{}</td><td class=\"n\">{:+.4}</td><td class=\"n\">{:+.4}</td></tr>",
            escaped(&touch.id),
            touch.residual_before * 1e3,
            touch.residual_after * 1e3
        );
    }
    html += "</table>\n";
    html
}

/// The page `ips diagnose SESSION` writes as `SESSION.diagnosis.html`, for the session named
/// `session`: [`diagnosis_section`] in a self-contained page (no script, nothing fetched).
pub fn diagnosis_page(session: &str, report: &DiagnoseReport) -> String {
    format!(
        "<!doctype html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\
         <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\
         <title>Diagnosis of {session}</title>\n<style>\
         body{{font-family:sans-serif;margin:1.5em;max-width:80em}}\
         table{{border-collapse:collapse;margin:0.5em 0 1.5em}}\
         td,th{{border:1px solid #ccc;padding:0.3em 0.6em;text-align:left}}\
         td.n{{text-align:right;font-variant-numeric:tabular-nums}}\
         .verdict{{font-size:1.3em}} figure{{margin:0;overflow-x:auto}}\
         </style></head><body>\n<h1>Diagnosis of {session}</h1>\n{}</body></html>\n",
        diagnosis_section(report),
        session = escaped(session)
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use protocol::Pose;
    use protocol::reports::{EffectFit, FitSummary, InspectionResidual};

    fn report(verdict: &str, id: &str) -> DiagnoseReport {
        let summary = FitSummary {
            loo_rms: 2e-4,
            max: 3e-4,
            rms: 1e-4,
        };
        DiagnoseReport {
            verdict: verdict.to_owned(),
            effect: Some(EffectFit {
                bic: -10.0,
                name: "probe_radius".to_owned(),
                params: [("ball_radius_delta_m".to_owned(), 5e-4)].into(),
                stderr: [("ball_radius_delta_m".to_owned(), 1e-5)].into(),
            }),
            alternatives: vec![],
            before: summary.clone(),
            after: summary,
            pose_before: Pose::new([0.0; 3], [0.0; 3]),
            pose_after: Pose::new([0.0; 3], [0.0; 3]),
            inspections: vec![
                InspectionResidual {
                    id: id.to_owned(),
                    residual_after: 1e-5,
                    residual_before: 4e-4,
                    ball_centre_after: None,
                },
                InspectionResidual {
                    id: "i2".to_owned(),
                    residual_after: f64::NAN,
                    residual_before: -2e-4,
                    ball_centre_after: None,
                },
            ],
            explanation: "a <test>".to_owned(),
            chi_square: [30.0, 2.0],
            plot: None,
            page: None,
            base_frame: None,
            noise_sigma_m: Some(2e-5),
        }
    }

    #[test]
    fn names_from_the_report_are_escaped_everywhere() {
        let page = diagnosis_page("a&b.json", &report("effect", "<script>x</script>"));
        assert!(!page.contains("<script>"), "{page}");
        assert!(page.contains("&lt;script&gt;x&lt;/script&gt;"));
        assert!(page.contains("a &lt;test&gt;"));
        assert!(page.contains("Diagnosis of a&amp;b.json"));
    }

    #[test]
    fn the_scatter_panel_is_drawn_only_for_an_applied_effect() {
        let applied = diagnosis_svg(&report("effect", "i1"));
        assert!(applied.contains("what probe_radius explains"));
        assert!(applied.contains("green band"));
        let ambiguous = diagnosis_svg(&report("ambiguous", "i1"));
        assert!(ambiguous.contains("nothing applied (best candidate probe_radius)"));
        assert!(ambiguous.contains("nothing to plot against"));
        assert!(!ambiguous.contains("<circle"));
    }

    #[test]
    fn a_residual_that_is_not_a_number_draws_a_minimal_bar_not_a_broken_one() {
        let svg = diagnosis_svg(&report("effect", "i1"));
        assert!(!svg.contains("NaN"), "{svg}");
        assert!(!svg.contains("inf"), "{svg}");
    }
}
