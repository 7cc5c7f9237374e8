//! The diagnosis as a page people open in a browser (`ips diagnose SESSION` writes it next to the
//! session as `SESSION.diagnosis.html`): the verdict and the effect with its error in the units
//! people read, the residuals before and after (the same SVG as `.diagnosis.svg`, inline), every
//! candidate that lost and why, and the touches. One self-contained file: no script, no network.

use std::fmt::Write as _;

use align_core::io::export::xml_escaped as escaped;
use align_service::jobs::units::person_unit;
use protocol::reports::DiagnoseReport;

fn mm(value_m: f64) -> String {
    format!("{:.4}", value_m * 1e3 + 0.0)
}

/// The page for `report` of the session named `session`, with the residual plot `svg`.
pub fn diagnosis_page(session: &str, report: &DiagnoseReport, svg: &str) -> String {
    let mut page = format!(
        "<!doctype html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\
         <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\
         <title>Diagnosis of {session}</title>\n<style>\
         body{{font-family:sans-serif;margin:1.5em;max-width:80em}}\
         table{{border-collapse:collapse;margin:0.5em 0 1.5em}}\
         td,th{{border:1px solid #ccc;padding:0.3em 0.6em;text-align:left}}\
         td.n{{text-align:right;font-variant-numeric:tabular-nums}}\
         .verdict{{font-size:1.3em}} figure{{margin:0;overflow-x:auto}}\
         </style></head><body>\n<h1>Diagnosis of {session}</h1>\n\
         <p class=\"verdict\">Verdict: <strong id=\"verdict\">{}</strong></p>\n<p>{}</p>\n",
        escaped(&report.verdict),
        escaped(&report.explanation),
        session = escaped(session)
    );
    match &report.effect {
        Some(effect) if report.verdict == "effect" => {
            let _ = write!(
                page,
                "<h2>Applied: {}</h2>\n<table><tr><th>parameter</th><th>value</th><th>standard error</th></tr>\n",
                escaped(&effect.name)
            );
            for (name, value) in &effect.params {
                let (factor, unit, decimals) = person_unit(name);
                let stderr = effect.stderr.get(name).copied().unwrap_or(f64::NAN);
                let _ = writeln!(
                    page,
                    "<tr><td>{}</td><td class=\"n\">{:+.decimals$} {unit}</td><td class=\"n\">{:.decimals$} {unit}</td></tr>",
                    escaped(name),
                    value * factor,
                    stderr * factor
                );
            }
            page += "</table>\n";
        }
        Some(effect) => {
            let _ = writeln!(
                page,
                "<h2>Nothing applied</h2>\n<p>The best candidate, {}, is not applied: see the verdict.</p>",
                escaped(&effect.name)
            );
        }
        None => page += "<h2>Nothing applied</h2>\n",
    }
    let (before, after) = (&report.before, &report.after);
    let _ = write!(
        page,
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
    let _ = write!(page, "<h2>Residuals</h2>\n<figure>{svg}</figure>\n");
    page += "<h2>Candidates not chosen</h2>\n<table id=\"alternatives\"><tr><th>candidate</th><th>BIC</th><th>leave-one-out rms (mm)</th><th>why</th></tr>\n";
    for alternative in &report.alternatives {
        let _ = writeln!(
            page,
            "<tr><td>{}</td><td class=\"n\">{}</td><td class=\"n\">{}</td><td>{}</td></tr>",
            escaped(&alternative.name),
            alternative
                .bic
                .map_or("-".to_owned(), |b| format!("{b:.1}")),
            alternative.loo_rms.map_or("-".to_owned(), mm),
            escaped(&alternative.reason)
        );
    }
    page += "</table>\n<h2>Touches</h2>\n<table id=\"touches\"><tr><th>touch</th><th>residual before (mm)</th><th>after (mm)</th></tr>\n";
    for touch in &report.inspections {
        let _ = writeln!(
            page,
            "<tr><td>{}</td><td class=\"n\">{:+.4}</td><td class=\"n\">{:+.4}</td></tr>",
            escaped(&touch.id),
            touch.residual_before * 1e3,
            touch.residual_after * 1e3
        );
    }
    page += "</table>\n</body></html>\n";
    page
}
