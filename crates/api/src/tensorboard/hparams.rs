//! The run's settings as TensorBoard hyperparameters (the HParams tab lists runs with their
//! settings beside their metrics): a summary tagged `_hparams_/session_start_info` whose
//! metadata holds the hparams plugin's `HParamsPluginData` with a `SessionStartInfo`
//! (`tensorboard/plugins/hparams/plugin_data.proto`, version 0), each setting a
//! `google.protobuf.Value`. Settings are the job's document flattened to dotted keys
//! (`config.learning_rate`); lists become their JSON text.

use std::collections::BTreeMap;

use super::{Event, PluginData, Summary, SummaryMetadata, Value, encode};

/// `HParamsPluginData`, holding a session's start.
#[derive(Clone, PartialEq, prost::Message)]
pub struct PluginContent {
    #[prost(int32, tag = "1")]
    pub version: i32,
    #[prost(message, optional, tag = "3")]
    pub session_start_info: Option<SessionStartInfo>,
}

/// `SessionStartInfo`.
#[derive(Clone, PartialEq, prost::Message)]
pub struct SessionStartInfo {
    #[prost(btree_map = "string, message", tag = "1")]
    pub hparams: BTreeMap<String, ProtoValue>,
    #[prost(double, tag = "5")]
    pub start_time_secs: f64,
}

/// `google.protobuf.Value`: the kinds a setting takes.
#[derive(Clone, PartialEq, prost::Message)]
pub struct ProtoValue {
    #[prost(oneof = "Kind", tags = "2, 3, 4")]
    pub kind: Option<Kind>,
}

#[derive(Clone, PartialEq, prost::Oneof)]
pub enum Kind {
    #[prost(double, tag = "2")]
    Number(f64),
    #[prost(string, tag = "3")]
    Text(String),
    #[prost(bool, tag = "4")]
    Bool(bool),
}

/// A JSON document's leaves under dotted keys (`config.learning_rate`); nulls are left out.
pub fn flatten(document: &serde_json::Value) -> Vec<(String, serde_json::Value)> {
    fn walk(prefix: &str, value: &serde_json::Value, out: &mut Vec<(String, serde_json::Value)>) {
        match value {
            serde_json::Value::Object(map) => {
                for (k, v) in map {
                    let key = if prefix.is_empty() {
                        k.clone()
                    } else {
                        format!("{prefix}.{k}")
                    };
                    walk(&key, v, out);
                }
            }
            serde_json::Value::Null => {}
            other => out.push((prefix.to_string(), other.clone())),
        }
    }
    let mut out = Vec::new();
    walk("", document, &mut out);
    out
}

/// The settings' hparams summary at step 0.
pub fn session_start(settings: &serde_json::Value, start: f64) -> Vec<u8> {
    let hparams = flatten(settings)
        .into_iter()
        .map(|(key, value)| {
            let kind = match value {
                serde_json::Value::Number(n) => Kind::Number(n.as_f64().unwrap_or(0.0)),
                serde_json::Value::Bool(b) => Kind::Bool(b),
                serde_json::Value::String(s) => Kind::Text(s),
                other => Kind::Text(other.to_string()),
            };
            (key, ProtoValue { kind: Some(kind) })
        })
        .collect();
    let content = PluginContent {
        version: 0,
        session_start_info: Some(SessionStartInfo {
            hparams,
            start_time_secs: start,
        }),
    };
    encode(&Event {
        wall_time: start,
        step: 0,
        file_version: None,
        summary: Some(Summary {
            value: vec![Value {
                tag: "_hparams_/session_start_info".into(),
                simple_value: None,
                tensor: None,
                metadata: Some(SummaryMetadata {
                    plugin_data: Some(PluginData {
                        plugin_name: "hparams".into(),
                        content: prost::Message::encode_to_vec(&content),
                    }),
                }),
            }],
        }),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_document_flattens_to_dotted_leaves() {
        let flat = flatten(&serde_json::json!({
            "algorithm": "crm-ppo",
            "config": {"gamma": 0.99, "hidden": [256, 256]},
            "none": null,
            "curriculum": true,
        }));
        let keys: Vec<&str> = flat.iter().map(|(k, _)| k.as_str()).collect();
        assert_eq!(
            keys,
            ["algorithm", "config.gamma", "config.hidden", "curriculum"]
        );
        assert_eq!(flat[2].1, serde_json::json!([256, 256]));
    }
}
