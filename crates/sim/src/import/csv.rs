//! The authors' task table, `crm_ppo/topo/pos_all.csv`, read as their code reads it (pandas,
//! then `ast.literal_eval` on the vector columns), with its quirks: vectors are quoted Python
//! lists (`"[0.78, -0.455, 0.2]"`), numbers may lack a leading digit (`.0530869`) or carry
//! spaces (`"[0.77, -0.45, 0.22 ]"`), and names vary in case (`press`, `Lever`,
//! `Handle-grasp`). Every error names the file, the line and the column.

use std::path::Path;

use crate::benchmark::{Objective, Topology};
use crate::error::{Result, invalid_at};

/// The columns the import reads, by the header's names.
pub const COLUMNS: [&str; 9] = [
    "Task ID",
    "Object",
    "Object ID",
    "Affordance",
    "Trans",
    "Orientation",
    "Topology",
    "p_obj",
    "q_obj",
];

/// One task row.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// The file's line (the header is line 1).
    pub line: usize,
    pub task: u32,
    /// The object's category (`faucet`, `handle_bottle`).
    pub category: String,
    /// The AffordPose id: `objects/<id>/`.
    pub object: String,
    pub objective: Objective,
    /// The hand's translation in the object frame (m).
    pub trans: [f32; 3],
    /// The hand's orientation in the object frame, `[x, y, z, w]`.
    pub orientation: [f32; 4],
    pub topology: Topology,
    pub p_obj: [f32; 3],
    /// The object's orientation on the table, `[x, y, z, w]`.
    pub q_obj: [f32; 4],
    /// The object's random turn about the vertical, `[lower, upper]` (rad).
    pub turn: [f32; 2],
}

/// Splits CSV text into records of fields (RFC 4180 quoting: `"a, b"`, `""` for a quote),
/// each with its line number.
pub fn records(text: &str) -> Vec<(usize, Vec<String>)> {
    let mut out = Vec::new();
    let mut fields = Vec::new();
    let mut field = String::new();
    let mut quoted = false;
    let mut line = 1;
    let mut start = 1;
    let mut chars = text.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            '"' if quoted && chars.peek() == Some(&'"') => {
                field.push('"');
                chars.next();
            }
            '"' => quoted = !quoted,
            ',' if !quoted => fields.push(std::mem::take(&mut field)),
            '\r' if !quoted => {}
            '\n' if !quoted => {
                fields.push(std::mem::take(&mut field));
                if fields.iter().any(|f| !f.trim().is_empty()) {
                    out.push((start, std::mem::take(&mut fields)));
                }
                fields.clear();
                line += 1;
                start = line;
            }
            '\n' => {
                field.push(c);
                line += 1;
            }
            _ => field.push(c),
        }
    }
    fields.push(field);
    if fields.iter().any(|f| !f.trim().is_empty()) {
        out.push((start, fields));
    }
    out
}

/// A number as Python writes it: `.5`, `0.`, `-9.8e-08`, with spaces around.
pub fn number(text: &str) -> Option<f32> {
    let t = text.trim();
    let valid = !t.is_empty()
        && t.chars().all(|c| c.is_ascii_digit() || "+-.eE".contains(c))
        && t.chars().any(|c| c.is_ascii_digit());
    valid
        .then(|| t.parse::<f32>().ok())
        .flatten()
        .filter(|v| v.is_finite())
}

/// A Python list of `N` numbers: `[a, b, c]` (parentheses too, as `ast.literal_eval` takes
/// tuples).
pub fn vector<const N: usize>(text: &str) -> std::result::Result<[f32; N], String> {
    let t = text.trim();
    let inner = t
        .strip_prefix('[')
        .and_then(|s| s.strip_suffix(']'))
        .or_else(|| t.strip_prefix('(').and_then(|s| s.strip_suffix(')')))
        .ok_or_else(|| format!("expected a list of {N} numbers like [0.1, 0.2], got {t:?}"))?;
    let parts: Vec<&str> = inner.split(',').collect();
    if parts.len() != N {
        return Err(format!(
            "expected {N} numbers, got {} in {t:?}",
            parts.len()
        ));
    }
    let mut out = [0.0; N];
    for (slot, part) in out.iter_mut().zip(&parts) {
        *slot = number(part).ok_or_else(|| format!("{:?} is not a number", part.trim()))?;
    }
    Ok(out)
}

/// The authors' affordance names as objectives.
pub fn objective(text: &str) -> Option<Objective> {
    let key = text.trim().to_ascii_lowercase().replace(['-', ' '], "_");
    Objective::ALL.into_iter().find(|o| o.name() == key)
}

/// The authors' topology names (`inSiAd2`, `platform`) as ours, ignoring case.
pub fn topology(text: &str) -> Option<Topology> {
    let key = text.trim();
    Topology::ALL
        .into_iter()
        .find(|t| t.name().eq_ignore_ascii_case(key))
}

/// Parses the table, naming `path`, the line and the column of the first bad value.
pub fn parse(text: &str, path: &Path) -> Result<Vec<Row>> {
    let mut records = records(text).into_iter();
    let Some((_, header)) = records.next() else {
        return Err(invalid_at(path, "line 1", "the file is empty"));
    };
    let header: Vec<String> = header.iter().map(|h| h.trim().to_string()).collect();
    let mut index = std::collections::BTreeMap::new();
    for name in COLUMNS.iter().chain(&["lower", "upper"]) {
        let at = header.iter().position(|h| h == name).ok_or_else(|| {
            invalid_at(
                path,
                "line 1",
                format!("no column {name:?} in the header {header:?}"),
            )
        })?;
        index.insert(*name, at);
    }
    let mut rows = Vec::new();
    for (line, fields) in records {
        let cell = |name: &str| -> Result<&str> {
            fields
                .get(index[name])
                .map(String::as_str)
                .ok_or_else(|| invalid_at(path, format!("line {line}, column {name:?}"), "missing"))
        };
        let bad = |name: &str, message: String| {
            invalid_at(path, format!("line {line}, column {name:?}"), message)
        };
        let task = cell("Task ID")?;
        let task = task
            .trim()
            .parse::<u32>()
            .map_err(|_| bad("Task ID", format!("{task:?} is not a task number")))?;
        let category = cell("Object")?.trim().to_ascii_lowercase();
        let object = cell("Object ID")?.trim().to_string();
        if object.is_empty() || !object.chars().all(|c| c.is_ascii_alphanumeric()) {
            return Err(bad(
                "Object ID",
                format!("{object:?} is not an AffordPose id"),
            ));
        }
        let affordance = cell("Affordance")?;
        let objective = objective(affordance).ok_or_else(|| {
            bad(
                "Affordance",
                format!(
                    "unknown objective {affordance:?} (known: Lever, Twist, press, \
                     Handle-grasp, Wrap-grasp, lift, pull)"
                ),
            )
        })?;
        let name = cell("Topology")?;
        let topology = topology(name).ok_or_else(|| {
            bad(
                "Topology",
                format!(
                    "unknown topology {name:?} (known: inSiAd2, platform, poPmAb25, pPdAb2, \
                     pPdAb23, pPdAb25)"
                ),
            )
        })?;
        let vec3 = |name: &str| vector::<3>(cell(name)?).map_err(|m| bad(name, m));
        let quat = |name: &str| -> Result<[f32; 4]> {
            let q = vector::<4>(cell(name)?).map_err(|m| bad(name, m))?;
            let norm = q.iter().map(|v| v * v).sum::<f32>().sqrt();
            if !(0.9..=1.1).contains(&norm) {
                return Err(bad(
                    name,
                    format!("{q:?} is not a unit quaternion [x, y, z, w] (norm {norm:.3})"),
                ));
            }
            Ok(q.map(|v| v / norm))
        };
        let scalar = |name: &str| -> Result<f32> {
            let text = cell(name)?;
            number(text).ok_or_else(|| bad(name, format!("{text:?} is not a number")))
        };
        let turn = [scalar("lower")?, scalar("upper")?];
        if turn[0] > turn[1] {
            return Err(bad(
                "upper",
                format!("{} is below lower {}", turn[1], turn[0]),
            ));
        }
        rows.push(Row {
            line,
            task,
            category,
            object,
            objective,
            trans: vec3("Trans")?,
            orientation: quat("Orientation")?,
            topology,
            p_obj: vec3("p_obj")?,
            q_obj: quat("q_obj")?,
            turn,
        });
    }
    if rows.is_empty() {
        return Err(invalid_at(path, "line 2", "the table has no task rows"));
    }
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    const HEADER: &str = "Task ID,Object,Object ID,side,Affordance,Affordance ID,Class ID,o2h,\
                          Trans,Orientation,Topology,p_obj,q_obj,lower,upper\n";

    fn table(row: &str) -> String {
        format!("{HEADER}{row}\n")
    }

    const KNIFE: &str = "4,knife,115,0,Handle-grasp,1,2,\"(+x, +x)(+y, +z)(+z, -y)\",\
                         \"[-0.000204797, -0.0185244, 0.0481876]\",\
                         \"[-0.257982, 0.684198, 0.680073, .0530869]\",poPmAb25,\
                         \"[0.77, -0.45, 0.22 ]\",\"[0.6758314806488387, 0.1598809464651245, \
                         0.16563695266234274, 0.7001816140360636]\",0,0.2";

    #[test]
    fn the_authors_quirks_parse() {
        let rows = parse(&table(KNIFE), Path::new("pos_all.csv")).expect("parses");
        let row = &rows[0];
        assert_eq!((row.line, row.task), (2, 4));
        assert_eq!(row.object, "115");
        assert_eq!(row.objective, Objective::HandleGrasp);
        assert_eq!(row.topology, Topology::PoPmAb25);
        // `.0530869`, and a list with a space before its bracket.
        assert!((row.orientation[3] - 0.0530869).abs() < 1e-3);
        assert_eq!(row.p_obj, [0.77, -0.45, 0.22]);
        assert_eq!(row.turn, [0.0, 0.2]);
    }

    #[test]
    fn names_map_whatever_their_case() {
        assert_eq!(objective("press"), Some(Objective::Press));
        assert_eq!(objective("Lever"), Some(Objective::Lever));
        assert_eq!(objective("Wrap-grasp"), Some(Objective::WrapGrasp));
        assert_eq!(topology("inSiAd2"), Some(Topology::InSiAd2));
        assert_eq!(topology("platform"), Some(Topology::Platform));
        assert_eq!(topology("pPdAb23"), Some(Topology::PPdAb23));
        assert_eq!(topology("power"), None);
    }

    #[test]
    fn numbers_and_lists_as_python_writes_them() {
        assert_eq!(number(" .5 "), Some(0.5));
        assert_eq!(number("0."), Some(0.0));
        assert_eq!(number("-9.80207e-08"), Some(-9.80207e-08));
        assert_eq!(number("abc"), None);
        assert_eq!(number("nan"), None);
        assert_eq!(number(""), None);
        assert_eq!(vector::<3>("(1, 2, 3)"), Ok([1.0, 2.0, 3.0]));
        assert!(vector::<3>("[1, 2]").is_err());
        assert!(vector::<3>("1, 2, 3").is_err());
    }

    #[test]
    fn quoted_fields_keep_commas_and_quotes() {
        let rec = records("a,\"b, c\",\"say \"\"hi\"\"\"\r\n\n1,2,3");
        assert_eq!(rec.len(), 2);
        assert_eq!(rec[0].1, vec!["a", "b, c", "say \"hi\""]);
        assert_eq!(rec[1], (3, vec!["1".into(), "2".into(), "3".into()]));
    }

    fn error_of(row: &str) -> String {
        parse(&table(row), Path::new("topo/pos_all.csv"))
            .expect_err("refused")
            .to_string()
    }

    #[test]
    fn bad_values_name_the_file_line_and_column() {
        let bad_number = KNIFE.replace(".0530869", ".05.30869");
        let message = error_of(&bad_number);
        assert!(message.contains("topo/pos_all.csv"), "{message}");
        assert!(
            message.contains("line 2, column \"Orientation\""),
            "{message}"
        );

        let message = error_of(&KNIFE.replace("poPmAb25", "power"));
        assert!(message.contains("column \"Topology\""), "{message}");
        assert!(message.contains("\"power\""), "{message}");

        let message = error_of(&KNIFE.replace("Handle-grasp", "Juggle"));
        assert!(message.contains("column \"Affordance\""), "{message}");

        let message = error_of(&KNIFE.replace("0.6758314806488387", "6.7"));
        assert!(message.contains("column \"q_obj\""), "{message}");
        assert!(message.contains("unit quaternion"), "{message}");

        let message = error_of(&KNIFE.replace("115", "../x"));
        assert!(message.contains("column \"Object ID\""), "{message}");

        let message = parse("Task ID,Object\n1,knife\n", Path::new("t.csv"))
            .expect_err("refused")
            .to_string();
        assert!(
            message.contains("line 1") && message.contains("Object ID"),
            "{message}"
        );
    }
}
