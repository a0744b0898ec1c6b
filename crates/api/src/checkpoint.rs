//! What the coordinator checks in a checkpoint without loading it: the safetensors layout
//! (an 8-byte little-endian header length, a JSON header, the tensor bytes) and the
//! crm-grasp header in its metadata (format, algorithm, environment version). Workers and
//! users upload checkpoints; both go through [`inspect`], so the service never stores a
//! file its workers would refuse for its format or environment.

use std::collections::HashMap;

use serde::Deserialize;

use crate::Algorithm;

/// The environment version the workers of this build run (`grasp_sim::ENV_VERSION`, which a
/// worker test keeps equal): checkpoints of another version are refused.
pub const ENV_VERSION: &str = "grasp-sim/0.1.0/obs38/v4";

/// The format tag in every checkpoint header (`crm_learn::checkpoint::FORMAT`).
pub const FORMAT: &str = "crm-grasp-checkpoint/1";

/// The metadata key that holds the crm-grasp header.
const HEADER_KEY: &str = "crm_grasp";

/// Largest safetensors JSON header read (the format's own limit is 100 MB; ours are a few
/// kilobytes).
const MAX_HEADER: u64 = 16 << 20;

/// What a checkpoint says about itself, as far as the coordinator needs.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct CheckpointInfo {
    pub algorithm: Algorithm,
    pub env_version: String,
    pub spec_hash: String,
    pub seed: u64,
    /// Environment steps trained.
    pub steps: u64,
    /// How it was made: one object per training run that led to it, oldest first
    /// (`crm_learn::LineageStage`); empty for a file written without a lineage.
    pub lineage: Vec<serde_json::Value>,
}

/// Why a file is not a checkpoint this service can use.
#[derive(Debug, PartialEq, Eq, thiserror::Error)]
pub enum CheckpointError {
    #[error("not a safetensors file: {0}")]
    NotSafetensors(String),
    #[error("a safetensors file without a crm-grasp header (not a policy checkpoint)")]
    NoHeader,
    #[error("malformed crm-grasp header: {0}")]
    Header(String),
    #[error("format {found:?}, expected {FORMAT:?}")]
    Format { found: String },
    #[error("unknown algorithm {0:?}")]
    Algorithm(String),
    #[error("made for environment {found:?}; this service runs {ENV_VERSION:?}")]
    EnvVersion { found: String },
}

impl CheckpointError {
    /// Whether the file is a readable checkpoint made for something else (another
    /// environment version), as opposed to a file that is not one at all.
    pub fn is_mismatch(&self) -> bool {
        matches!(self, Self::EnvVersion { .. })
    }
}

#[derive(Deserialize)]
struct TensorEntry {
    data_offsets: (u64, u64),
}

#[derive(Deserialize)]
struct Header {
    format: String,
    algorithm: String,
    env_version: String,
    spec_hash: String,
    #[serde(default)]
    seed: u64,
    steps: u64,
    #[serde(default)]
    lineage: Vec<serde_json::Value>,
}

/// How many leading bytes of a file [`inspect`] needs: the 8-byte length and the JSON
/// header. `None` when the first 8 bytes are missing or name an absurd length.
pub fn header_len(prefix: &[u8]) -> Option<u64> {
    let bytes: [u8; 8] = prefix.get(..8)?.try_into().ok()?;
    let n = u64::from_le_bytes(bytes);
    (n <= MAX_HEADER).then_some(8 + n)
}

/// Checks `prefix` (at least the first [`header_len`] bytes of a file of `file_len` bytes):
/// a safetensors layout whose tensors fit the file exactly, a crm-grasp header of our format,
/// a known algorithm and this build's environment version.
pub fn inspect(prefix: &[u8], file_len: u64) -> Result<CheckpointInfo, CheckpointError> {
    let bad = |m: &str| CheckpointError::NotSafetensors(m.to_string());
    let end = header_len(prefix).ok_or_else(|| bad("no valid 8-byte header length"))?;
    if end > file_len || end > prefix.len() as u64 {
        return Err(bad("shorter than its header length says"));
    }
    let json = &prefix[8..end as usize];
    let entries: HashMap<String, serde_json::Value> =
        serde_json::from_slice(json).map_err(|e| bad(&format!("header is not JSON: {e}")))?;
    let mut data_len = 0u64;
    let mut metadata = None;
    for (name, value) in entries {
        if name == "__metadata__" {
            metadata = Some(value);
            continue;
        }
        let entry: TensorEntry =
            serde_json::from_value(value).map_err(|e| bad(&format!("tensor {name:?}: {e}")))?;
        let (begin, stop) = entry.data_offsets;
        if begin > stop {
            return Err(bad(&format!("tensor {name:?}: offsets out of order")));
        }
        data_len = data_len.max(stop);
    }
    let needed = end
        .checked_add(data_len)
        .ok_or_else(|| bad("tensor offsets beyond 2^64 bytes"))?;
    if needed != file_len {
        return Err(bad(&format!(
            "the tensors need {needed} bytes, the file has {file_len}"
        )));
    }
    let header = metadata
        .as_ref()
        .and_then(|m| m.get(HEADER_KEY))
        .and_then(|h| h.as_str())
        .ok_or(CheckpointError::NoHeader)?;
    let header: Header =
        serde_json::from_str(header).map_err(|e| CheckpointError::Header(e.to_string()))?;
    if header.format != FORMAT {
        return Err(CheckpointError::Format {
            found: header.format,
        });
    }
    if i64::try_from(header.steps).is_err() {
        // Stores keep steps as SQL integers (i64).
        return Err(CheckpointError::Header(format!(
            "steps: {} is beyond 2^63 - 1",
            header.steps
        )));
    }
    let algorithm = Algorithm::parse(&header.algorithm)
        .ok_or_else(|| CheckpointError::Algorithm(header.algorithm.clone()))?;
    if header.env_version != ENV_VERSION {
        return Err(CheckpointError::EnvVersion {
            found: header.env_version,
        });
    }
    Ok(CheckpointInfo {
        algorithm,
        env_version: header.env_version,
        spec_hash: header.spec_hash,
        seed: header.seed,
        steps: header.steps,
        lineage: header.lineage,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A safetensors file with one 4-byte tensor and `header` as its crm-grasp metadata.
    fn file(header: Option<&str>) -> Vec<u8> {
        let mut json = serde_json::json!({
            "w": {"dtype": "F32", "shape": [1], "data_offsets": [0, 4]},
        });
        if let Some(h) = header {
            json["__metadata__"] = serde_json::json!({ HEADER_KEY: h });
        }
        let json = json.to_string();
        let mut bytes = (json.len() as u64).to_le_bytes().to_vec();
        bytes.extend(json.as_bytes());
        bytes.extend([0u8; 4]);
        bytes
    }

    fn header(algorithm: &str, env: &str) -> String {
        serde_json::json!({
            "format": FORMAT, "algorithm": algorithm, "env_version": env,
            "spec_hash": "abc", "seed": 3, "steps": 4096,
        })
        .to_string()
    }

    #[test]
    fn a_checkpoint_of_this_environment_is_read() {
        let bytes = file(Some(&header("crm-ppo", ENV_VERSION)));
        let info = inspect(&bytes, bytes.len() as u64).expect("valid");
        assert_eq!(info.algorithm, Algorithm::CrmPpo);
        assert_eq!((info.steps, info.seed), (4096, 3));
        assert_eq!(header_len(&bytes), Some(bytes.len() as u64 - 4));
    }

    #[test]
    fn files_that_are_not_checkpoints_are_refused_with_the_reason() {
        assert!(matches!(
            inspect(b"hello", 5),
            Err(CheckpointError::NotSafetensors(_))
        ));
        let plain = file(None);
        assert_eq!(
            inspect(&plain, plain.len() as u64),
            Err(CheckpointError::NoHeader)
        );
        let good = file(Some(&header("crm-ppo", ENV_VERSION)));
        let short = inspect(&good[..good.len() - 1], good.len() as u64 - 1);
        assert!(
            matches!(short, Err(CheckpointError::NotSafetensors(m)) if m.contains("tensors need"))
        );
        let sac = file(Some(&header("dqn", ENV_VERSION)));
        assert_eq!(
            inspect(&sac, sac.len() as u64),
            Err(CheckpointError::Algorithm("dqn".into()))
        );
        let old = file(Some(&header("ppo", "grasp-sim/0.1.0/obs38/v1")));
        let err = inspect(&old, old.len() as u64).expect_err("old version");
        assert!(err.is_mismatch());
        assert!(err.to_string().contains("v1"), "{err}");
        let mut huge = vec![0xff; 8];
        huge.extend([0u8; 8]);
        assert_eq!(header_len(&huge), None);
        let endless = {
            let json = serde_json::json!({
                "w": {"dtype": "F32", "shape": [1], "data_offsets": [0, u64::MAX]},
            })
            .to_string();
            let mut bytes = (json.len() as u64).to_le_bytes().to_vec();
            bytes.extend(json.as_bytes());
            bytes
        };
        let err = inspect(&endless, endless.len() as u64).expect_err("offsets past 2^64");
        assert!(err.to_string().contains("beyond 2^64"), "{err}");
        let steps = serde_json::json!({
            "format": FORMAT, "algorithm": "crm-ppo", "env_version": ENV_VERSION,
            "spec_hash": "abc", "seed": 3, "steps": u64::MAX,
        })
        .to_string();
        let far = file(Some(&steps));
        let err = inspect(&far, far.len() as u64).expect_err("steps beyond i64");
        assert!(err.to_string().contains("2^63"), "{err}");
    }
}
