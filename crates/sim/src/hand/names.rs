//! The closest names to one the description lacks, for errors: a missing prefix
//! (`palm` for `robot0:palm`) or a typo is the usual cause.

/// `; did you mean "robot0:palm"?` (up to three names), or nothing when no name is close.
pub fn did_you_mean<'a>(name: &str, candidates: impl IntoIterator<Item = &'a str>) -> String {
    let wanted = name.to_lowercase();
    let mut scored: Vec<(f64, &str)> = candidates
        .into_iter()
        .filter(|c| *c != name)
        .map(|c| {
            let lower = c.to_lowercase();
            // A name that ends or starts with the wanted one is a prefix or suffix away.
            let affix = lower.ends_with(&wanted) || lower.starts_with(&wanted);
            let score = if affix && !wanted.is_empty() {
                1.0
            } else {
                strsim::normalized_damerau_levenshtein(&wanted, &lower)
            };
            (score, c)
        })
        .filter(|(score, _)| *score >= 0.6)
        .collect();
    scored.sort_by(|a, b| b.0.total_cmp(&a.0).then_with(|| a.1.cmp(b.1)));
    scored.dedup_by(|a, b| a.1 == b.1);
    // Only names about as close as the closest: a shared prefix makes far names score well.
    let best = scored.first().map_or(0.0, |s| s.0);
    let names: Vec<String> = scored
        .iter()
        .filter(|(score, _)| *score >= best - 0.1)
        .take(3)
        .map(|(_, c)| format!("{c:?}"))
        .collect();
    match names.as_slice() {
        [] => String::new(),
        [one] => format!("; did you mean {one}?"),
        many => format!("; did you mean one of {}?", many.join(", ")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_prefix_or_a_typo_gets_the_closest_names() {
        let names = ["robot0:palm", "robot0:ffknuckle", "robot0:thbase", "world"];
        assert_eq!(
            did_you_mean("palm", names),
            "; did you mean \"robot0:palm\"?"
        );
        assert_eq!(
            did_you_mean("robot0:plam", names),
            "; did you mean \"robot0:palm\"?"
        );
        assert_eq!(did_you_mean("elbow", names), "");
    }
}
