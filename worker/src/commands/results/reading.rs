//! The reading at the end of each study's section of `RESULTS.md`, derived from the figures
//! above it and never typed by hand: the ordering by IQM, which intervals overlap, whether the
//! paper's ordering holds, where runs stopped early, and which runs almost never succeeded
//! while training.

use std::fmt::Write as _;

use super::paper::PAPER_ORDER;
use super::record::{Run, Study};
use super::stats::Estimate;

/// The reading, derived from the figures above.
pub fn reading(text: &mut String, study: &Study, algorithms: &[&str], iqms: &[(String, Estimate)]) {
    text.push_str("\n### Reading (derived from the figures above)\n\n");
    let mut order: Vec<&(String, Estimate)> = iqms.iter().collect();
    order.sort_by(|a, b| b.1.point.total_cmp(&a.1.point).then(a.0.cmp(&b.0)));
    let ranking: Vec<String> = order
        .iter()
        .map(|(a, e)| format!("{a} {:.3}", e.point))
        .collect();
    let _ = writeln!(
        text,
        "- Ordering by IQM of the sampled evaluation: {}.",
        ranking.join(" > ")
    );
    let mut overlaps = Vec::new();
    for (k, (a, x)) in order.iter().enumerate() {
        for (b, y) in order.iter().skip(k + 1) {
            if x.low <= y.high && y.low <= x.high {
                overlaps.push(format!("{a} and {b}"));
            }
        }
    }
    let _ = writeln!(
        text,
        "- Intervals that overlap (no clear difference): {}.",
        if overlaps.is_empty() {
            "none".to_string()
        } else {
            overlaps.join("; ")
        }
    );
    let single: Vec<&str> = algorithms
        .iter()
        .copied()
        .filter(|a| study.runs_of(a).count() < 2)
        .collect();
    if !single.is_empty() {
        let _ = writeln!(
            text,
            "- One run so far for {}: a bootstrap over one run has no spread, so those \
             intervals are points and say nothing yet about seed-to-seed variation.",
            single.join(", ")
        );
    }
    let ours: Vec<&str> = order
        .iter()
        .map(|(a, _)| a.as_str())
        .filter(|a| PAPER_ORDER.contains(a))
        .collect();
    let theirs: Vec<&str> = PAPER_ORDER
        .iter()
        .copied()
        .filter(|a| ours.contains(a))
        .collect();
    if ours.len() > 1 {
        let _ = writeln!(
            text,
            "- The paper's ordering of these learners is {}; here it is {}: {}.",
            theirs.join(" > "),
            ours.join(" > "),
            if ours == theirs {
                "the same"
            } else {
                "it differs"
            }
        );
    }
    for a in algorithms {
        let runs: Vec<&Run> = study.runs_of(a).collect();
        let stops: Vec<String> = runs
            .iter()
            .filter(|r| r.file.stopped_early)
            .map(|r| format!("seed {} at {}", r.file.seed, r.file.steps))
            .collect();
        let _ = writeln!(
            text,
            "- {a}: {} of {} runs stopped early{}.",
            stops.len(),
            runs.len(),
            if stops.is_empty() {
                String::new()
            } else {
                format!(" ({})", stops.join(", "))
            }
        );
    }
    // Runs that almost never succeeded while training: what their evaluation can be read as.
    let mut rare = Vec::new();
    for a in algorithms {
        for run in study.runs_of(a) {
            let (episodes, successes, length) = run.training_episodes();
            if episodes > 0 && (successes as f64) < 0.01 * episodes as f64 {
                rare.push(format!(
                    "{a} seed {} ({successes} of {episodes} training episodes, \
                     {length:.0} control steps long on average)",
                    run.file.seed
                ));
            }
        }
    }
    if !rare.is_empty() {
        let _ = writeln!(
            text,
            "- Runs that almost never succeeded while training (under 1% of their training \
             episodes): {}.",
            rare.join("; ")
        );
    }
}
