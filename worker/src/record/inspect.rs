//! Reading a `.rrd` file back (`crm record --inspect FILE`): its recordings, each entity with
//! the rows logged to it and the timelines used, and the text entries (stage transitions,
//! stage names) in order. For tests and for checking a recording on a machine without the
//! viewer.

use std::collections::{BTreeMap, BTreeSet};
use std::io::BufReader;
use std::path::Path;

use anyhow::Context;
use rerun::external::re_log_encoding::Decoder;
use rerun::log::{Chunk, LogMsg};
use serde::Serialize;

/// One entity of one recording.
#[derive(Debug, Default, Serialize)]
pub struct EntitySummary {
    pub rows: usize,
    pub timelines: BTreeSet<String>,
    /// The archetypes logged to it (`rerun.archetypes.Mesh3D`, ...).
    pub archetypes: BTreeSet<String>,
}

/// What a recording file holds.
#[derive(Debug, Default, Serialize)]
pub struct Summary {
    pub bytes: u64,
    /// Recording ids in the order they first appear.
    pub recordings: Vec<String>,
    /// Recording names (`job 3 · episode 1 · valve-twist seed 7`), in order.
    pub names: Vec<String>,
    /// Entity path -> rows and timelines, over all recordings.
    pub entities: BTreeMap<String, EntitySummary>,
    /// Text of `crm/transitions` log entries, in file order.
    pub transitions: Vec<String>,
    /// Text of `crm/stage` documents, in file order.
    pub stages: Vec<String>,
}

/// Decodes every message of `path`.
pub fn summarize(path: &Path) -> anyhow::Result<Summary> {
    let mut file =
        std::fs::File::open(path).with_context(|| format!("opening {}", path.display()))?;
    let bytes = file.metadata()?.len();
    let mut magic = [0u8; 3];
    if std::io::Read::read_exact(&mut file, &mut magic).is_err() || &magic != b"RRF" {
        anyhow::bail!(
            "{} is not a rerun recording (no RRF header)",
            path.display()
        );
    }
    std::io::Seek::rewind(&mut file)?;
    let messages = Decoder::<LogMsg>::decode_eager(BufReader::new(file))
        .with_context(|| format!("{} is not a rerun recording", path.display()))?;
    let mut summary = Summary {
        bytes,
        ..Summary::default()
    };
    let transition_text = rerun::TextLog::descriptor_text().component;
    let stage_text = rerun::TextDocument::descriptor_text().component;
    let recording_name = rerun::RecordingInfo::descriptor_name().component;
    for message in messages {
        let message = message.with_context(|| format!("decoding {}", path.display()))?;
        let LogMsg::ArrowMsg(store, arrow) = message else {
            continue;
        };
        let id = store.recording_id().to_string();
        if !summary.recordings.contains(&id) {
            summary.recordings.push(id);
        }
        let chunk = Chunk::from_arrow_msg(&arrow).context("a chunk")?;
        let entity = chunk.entity_path().to_string();
        let texts = |component| -> Vec<String> {
            chunk
                .iter_slices::<String>(component)
                .flatten()
                .map(|s| s.to_string())
                .collect()
        };
        match entity.as_str() {
            "/crm/transitions" => summary.transitions.extend(texts(transition_text)),
            "/crm/stage" => summary.stages.extend(texts(stage_text)),
            "/__properties" => summary.names.extend(texts(recording_name)),
            _ => {}
        }
        let entry = summary.entities.entry(entity).or_default();
        entry.rows += chunk.num_rows();
        entry
            .timelines
            .extend(chunk.timelines().keys().map(|t| t.to_string()));
        entry.archetypes.extend(
            chunk
                .component_descriptors()
                .filter_map(|d| d.archetype.map(|a| a.to_string())),
        );
    }
    Ok(summary)
}
