//! Checkpoints: the networks' tensors in one safetensors file whose metadata carries a JSON
//! header (algorithm, CRM spec hash, environment version, seed, steps, network layout,
//! config, lineage). Loading refuses a file that is not a checkpoint, or one made for another spec or
//! environment version, and says which.

use std::collections::HashMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::lineage::LineageStage;
use crate::network::{ActorCritic, Layout};
use crate::normalize::ObsNorm;

/// Tensor names of the observation statistics in a PPO-family checkpoint.
const NORM_MEAN: &str = "obs_norm.mean";
const NORM_VAR: &str = "obs_norm.var";
const NORM_COUNT: &str = "obs_norm.count";

/// Format tag in every header.
pub const FORMAT: &str = crm_api::checkpoint::FORMAT;
const HEADER_KEY: &str = "crm_grasp";

/// What a checkpoint says about itself.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CheckpointHeader {
    pub format: String,
    /// `crm-ppo`, `ippo`, `lppo`, `crm-sac` or `ppo`.
    pub algorithm: String,
    /// [`crm::Spec::hash`] of the machine it was trained in.
    pub spec_hash: String,
    /// The environment's version string (`grasp_sim::ENV_VERSION`).
    pub env_version: String,
    pub seed: u64,
    /// Environment steps trained.
    pub steps: u64,
    pub layout: Layout,
    pub hidden: Vec<usize>,
    /// The training configuration as JSON.
    pub config: serde_json::Value,
    /// The hidden layers' nonlinearity, written by CRM-SAC (`relu`); absent on PPO-family
    /// checkpoints (`tanh`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub activation: Option<String>,
    /// The world it was trained in (`grasp_sim::World::name`); absent: the built-in world.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub world: Option<String>,
    /// The hash of what shapes that world's observation and action (hand profile, spec,
    /// sensors: `grasp_sim::World::hash`); absent: the built-in world's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub world_hash: Option<String>,
    /// How it was made: every training run that led to it, oldest first, this one last
    /// (see `lineage.rs`). Empty in checkpoints written before headers kept it.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub lineage: Vec<LineageStage>,
    /// The whole training state of an unfinished run, so that a resume is the same run
    /// (`state.rs`; its arrays are the file's `state.*` tensors). Absent in a finished run's
    /// checkpoint, in CRM-SAC's and in those written before.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub state: Option<crate::state::RunState>,
}

/// What CRM-SAC checkpoints say in `activation` (older ones, with `tanh`, say nothing).
const SAC_ACTIVATION: &str = "relu";

/// Parameters as the (name, tensor) pairs a safetensors file stores.
fn named(
    params: &[(String, candle_core::Var)],
) -> impl Iterator<Item = (&str, &candle_core::Tensor)> {
    params
        .iter()
        .map(|(name, var)| (name.as_str(), var.as_tensor()))
}

/// Saving and loading checkpoints.
pub struct Checkpoint;

fn refuse(path: &Path, message: impl Into<String>) -> Error {
    Error::Checkpoint {
        path: path.display().to_string(),
        message: message.into(),
    }
}

impl Checkpoint {
    /// Writes the networks, their observation statistics and the header to `path`.
    pub fn save(net: &ActorCritic, header: &CheckpointHeader, path: &Path) -> Result<()> {
        Self::save_normalized(net.params(), net.norm(), header, &[], path)
    }

    /// [`Self::save`] with more tensors beside the network's (a run's training state,
    /// `state.rs`).
    pub fn save_with(
        net: &ActorCritic,
        header: &CheckpointHeader,
        extra: &[(String, candle_core::Tensor)],
        path: &Path,
    ) -> Result<()> {
        Self::save_normalized(net.params(), net.norm(), header, extra, path)
    }

    /// Every tensor of a checkpoint by name (a run's training state reads its `state.*`).
    pub fn tensors(path: &Path) -> Result<HashMap<String, candle_core::Tensor>> {
        let bytes = std::fs::read(path).map_err(|e| refuse(path, format!("cannot read: {e}")))?;
        candle_core::safetensors::load_buffer(&bytes, &candle_core::Device::Cpu)
            .map_err(|e| refuse(path, format!("cannot read tensors: {e}")))
    }

    /// Writes CRM-SAC's networks, their observation statistics, the header and `extra`
    /// tensors (a run's training state, `state.rs`) to `path`.
    pub fn save_sac(
        nets: &crate::sac::SacNets,
        header: &CheckpointHeader,
        extra: &[(String, candle_core::Tensor)],
        path: &Path,
    ) -> Result<()> {
        let header = CheckpointHeader {
            activation: Some(SAC_ACTIVATION.into()),
            ..header.clone()
        };
        Self::save_normalized(&nets.params, nets.norm(), &header, extra, path)
    }

    /// Writes named parameters with the observation statistics they were trained with.
    fn save_normalized(
        params: &[(String, candle_core::Var)],
        norm: &ObsNorm,
        header: &CheckpointHeader,
        extra: &[(String, candle_core::Tensor)],
        path: &Path,
    ) -> Result<()> {
        let (mean, var, count) = norm.to_parts();
        let device = &candle_core::Device::Cpu;
        let shape = (norm.stage_count(), norm.width());
        let stats = [
            (
                NORM_MEAN,
                candle_core::Tensor::from_vec(mean, shape, device)?,
            ),
            (NORM_VAR, candle_core::Tensor::from_vec(var, shape, device)?),
            (
                NORM_COUNT,
                candle_core::Tensor::from_vec(count, norm.stage_count(), device)?,
            ),
        ];
        Self::write(
            named(params)
                .chain(stats.iter().map(|(name, t)| (*name, t)))
                .chain(extra.iter().map(|(name, t)| (name.as_str(), t)))
                .collect(),
            header,
            path,
        )
    }

    /// Writes named parameters (any learner's) and the header to `path`.
    pub fn save_params(
        params: &[(String, candle_core::Var)],
        header: &CheckpointHeader,
        path: &Path,
    ) -> Result<()> {
        Self::write(named(params).collect(), header, path)
    }

    fn write(
        tensors: Vec<(&str, &candle_core::Tensor)>,
        header: &CheckpointHeader,
        path: &Path,
    ) -> Result<()> {
        let json = serde_json::to_string(header)
            .map_err(|e| refuse(path, format!("cannot encode header: {e}")))?;
        let metadata = HashMap::from([(HEADER_KEY.to_string(), json)]);
        safetensors::serialize_to_file(tensors, Some(metadata), path)
            .map_err(|e| refuse(path, format!("cannot write: {e}")))
    }

    /// Reads only the header.
    pub fn read_header(path: &Path) -> Result<CheckpointHeader> {
        let bytes = std::fs::read(path).map_err(|e| refuse(path, format!("cannot read: {e}")))?;
        Self::header_of(&bytes, path)
    }

    fn header_of(bytes: &[u8], path: &Path) -> Result<CheckpointHeader> {
        let (_, metadata) = safetensors::SafeTensors::read_metadata(bytes)
            .map_err(|e| refuse(path, format!("not a safetensors file ({e})")))?;
        let json = metadata
            .metadata()
            .as_ref()
            .and_then(|m| m.get(HEADER_KEY))
            .ok_or_else(|| refuse(path, "a safetensors file without a crm-grasp header"))?;
        let header: CheckpointHeader = serde_json::from_str(json)
            .map_err(|e| refuse(path, format!("malformed header: {e}")))?;
        if header.format != FORMAT {
            return Err(refuse(
                path,
                format!("format {:?}, this build reads {FORMAT:?}", header.format),
            ));
        }
        Ok(header)
    }

    /// Reads a checkpoint's bytes and header, refusing another machine or environment.
    fn read_checked(
        path: &Path,
        spec_hash: &str,
        env_version: &str,
    ) -> Result<(Vec<u8>, CheckpointHeader)> {
        let bytes = std::fs::read(path).map_err(|e| refuse(path, format!("cannot read: {e}")))?;
        let header = Self::header_of(&bytes, path)?;
        if header.spec_hash != spec_hash {
            return Err(refuse(
                path,
                format!(
                    "trained with crm spec {}, this machine's spec is {spec_hash}",
                    header.spec_hash
                ),
            ));
        }
        if header.env_version != env_version {
            return Err(refuse(
                path,
                format!(
                    "trained in environment {}, this is {env_version}",
                    header.env_version
                ),
            ));
        }
        Ok((bytes, header))
    }

    /// Sets every parameter from the checkpoint's tensor of the same name and shape; returns
    /// all the file's tensors.
    fn fill(
        bytes: &[u8],
        path: &Path,
        params: &[(String, candle_core::Var)],
    ) -> Result<HashMap<String, candle_core::Tensor>> {
        let tensors = candle_core::safetensors::load_buffer(bytes, &candle_core::Device::Cpu)
            .map_err(|e| refuse(path, format!("cannot read tensors: {e}")))?;
        for (name, var) in params {
            let tensor = tensors
                .get(name)
                .ok_or_else(|| refuse(path, format!("missing tensor {name}")))?;
            if tensor.shape() != var.shape() {
                return Err(refuse(
                    path,
                    format!(
                        "tensor {name} has shape {:?}, expected {:?}",
                        tensor.shape(),
                        var.shape()
                    ),
                ));
            }
            var.set(tensor)?;
        }
        Ok(tensors)
    }

    /// The observation statistics stored beside the networks.
    fn norm_of(
        tensors: &HashMap<String, candle_core::Tensor>,
        layout: crate::network::Layout,
        path: &Path,
    ) -> Result<ObsNorm> {
        let flat = |name: &str| -> Result<Vec<f64>> {
            let tensor = tensors.get(name).ok_or_else(|| {
                refuse(
                    path,
                    format!(
                        "no observation-normalizer statistics ({name}): made before they were \
                         stored; retrain it"
                    ),
                )
            })?;
            Ok(tensor
                .to_dtype(candle_core::DType::F64)?
                .flatten_all()?
                .to_vec1::<f64>()?)
        };
        let (mean, var, count) = (flat(NORM_MEAN)?, flat(NORM_VAR)?, flat(NORM_COUNT)?);
        ObsNorm::from_parts(layout.state_width, &mean, &var, &count)
            .filter(|n| n.stage_count() == layout.stages)
            .ok_or_else(|| {
                refuse(
                    path,
                    "observation-normalizer statistics do not fit the network",
                )
            })
    }

    /// Loads a PPO-family checkpoint made for this machine (`spec_hash`) and environment
    /// version.
    pub fn load(
        path: &Path,
        spec_hash: &str,
        env_version: &str,
    ) -> Result<(ActorCritic, CheckpointHeader)> {
        let (bytes, header) = Self::read_checked(path, spec_hash, env_version)?;
        if header.algorithm == "crm-sac" {
            return Err(refuse(path, "a crm-sac checkpoint: load it with load_sac"));
        }
        let mut net = ActorCritic::new(header.layout, &header.hidden, 0)?;
        let tensors = Self::fill(&bytes, path, net.params())?;
        net.set_norm(Self::norm_of(&tensors, header.layout, path)?)?;
        Ok((net, header))
    }

    /// Loads a CRM-SAC checkpoint made for this machine and environment version.
    pub fn load_sac(
        path: &Path,
        spec_hash: &str,
        env_version: &str,
    ) -> Result<(crate::sac::SacNets, CheckpointHeader)> {
        let (bytes, header) = Self::read_checked(path, spec_hash, env_version)?;
        if header.algorithm != "crm-sac" {
            return Err(refuse(
                path,
                format!("a {} checkpoint, not crm-sac", header.algorithm),
            ));
        }
        if header.activation.as_deref() != Some(SAC_ACTIVATION) {
            return Err(refuse(
                path,
                "a CRM-SAC checkpoint with tanh hidden layers (made before CRM-SAC took \
                 Stable-Baselines3's ReLU); train it again",
            ));
        }
        let mut nets = crate::sac::SacNets::new(header.layout, &header.hidden, 0)?;
        let tensors = Self::fill(&bytes, path, &nets.params)?;
        nets.set_norm(Self::norm_of(&tensors, header.layout, path)?)?;
        Ok((nets, header))
    }
}

impl LineageStage {
    /// The lineage a child of the checkpoint with header `parent` starts from: the parent's
    /// own, or, for a parent written without one, a stage made from what its header says.
    pub fn inherited(parent: &CheckpointHeader) -> Vec<LineageStage> {
        if !parent.lineage.is_empty() {
            return parent.lineage.clone();
        }
        vec![LineageStage {
            kind: "unrecorded".into(),
            algorithm: parent.algorithm.clone(),
            steps: parent.steps,
            wall_s: 0.0,
            seed: parent.seed,
            parent_sha256: None,
            world: parent.world.clone(),
            world_hash: parent.world_hash.clone(),
            corrections: None,
            imitation: None,
            command: None,
            job: serde_json::json!({ "config": parent.config }),
        }]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn header(net: &ActorCritic) -> CheckpointHeader {
        CheckpointHeader {
            format: FORMAT.into(),
            algorithm: "crm-ppo".into(),
            spec_hash: "abc123".into(),
            env_version: "grasp-sim/test".into(),
            seed: 5,
            steps: 1000,
            layout: net.layout(),
            hidden: net.hidden().to_vec(),
            config: serde_json::json!({"learning_rate": 3e-5}),
            activation: None,
            world: None,
            world_hash: None,
            lineage: vec![
                stage("train", None, None),
                stage(
                    "fine-tune",
                    Some("ab".repeat(32)),
                    Some(serde_json::json!({"demo_steps": 120, "epochs": 3})),
                ),
            ],
            state: None,
        }
    }

    fn stage(
        kind: &str,
        parent: Option<String>,
        imitation: Option<serde_json::Value>,
    ) -> crate::LineageStage {
        crate::LineageStage {
            kind: kind.into(),
            algorithm: "crm-ppo".into(),
            steps: 500,
            wall_s: 61.5,
            seed: 5,
            parent_sha256: parent,
            world: Some("crm".into()),
            world_hash: Some("f00d".into()),
            corrections: None,
            imitation,
            command: Some(vec![
                "crm".into(),
                "train".into(),
                "--seed".into(),
                "5".into(),
            ]),
            job: serde_json::json!({"algorithm": "crm-ppo", "steps": 500}),
        }
    }

    #[test]
    fn a_child_inherits_its_parents_lineage_or_a_stage_made_from_an_old_header() {
        let net = ActorCritic::new(
            Layout {
                state_width: 2,
                stages: 5,
                actions: 8,
            },
            &[4],
            1,
        )
        .expect("net");
        let parent = header(&net);
        assert_eq!(crate::LineageStage::inherited(&parent), parent.lineage);
        let old = CheckpointHeader {
            lineage: Vec::new(),
            ..parent
        };
        let made = crate::LineageStage::inherited(&old);
        assert_eq!(made.len(), 1);
        assert_eq!(made[0].kind, "unrecorded");
        assert_eq!((made[0].steps, made[0].seed), (1000, 5));
        let text = crate::lineage::describe(&header(&net).lineage);
        assert!(
            text.contains("2. fine-tune crm-ppo: 500 steps, 1.0 min, seed 5"),
            "{text}"
        );
        assert!(text.contains(&format!(
            "from the checkpoint with sha256 {}",
            "ab".repeat(32)
        )));
    }

    fn temp(name: &str) -> std::path::PathBuf {
        std::env::temp_dir().join(format!("crm-learn-{}-{name}", std::process::id()))
    }

    fn bits(net: &ActorCritic) -> Vec<u32> {
        net.flat_params()
            .expect("params")
            .into_iter()
            .map(f32::to_bits)
            .collect()
    }

    #[test]
    fn a_checkpoint_round_trips_bitwise_with_its_header() {
        let layout = Layout {
            state_width: 6,
            stages: 5,
            actions: 8,
        };
        let mut net = ActorCritic::new(layout, &[32, 32], 11).expect("net");
        net.update_norm(&[vec![1.0, 2.0, 3.0], vec![-1.0, 0.0, 5.0]], &[1, 1]);
        let path = temp("roundtrip.safetensors");
        let written = header(&net);
        Checkpoint::save(&net, &written, &path).expect("save");
        let (loaded, read) = Checkpoint::load(&path, "abc123", "grasp-sim/test").expect("load");
        assert_eq!(read, written);
        assert_eq!(bits(&loaded), bits(&net));
        assert_eq!(loaded.norm(), net.norm());
        let state = [vec![0.5, 2.5, 4.0]];
        let input = |n: &ActorCritic| n.input(&state, &[1]).expect("input").to_vec2::<f32>();
        assert_eq!(input(&loaded).expect("v"), input(&net).expect("v"));
        assert_eq!(Checkpoint::read_header(&path).expect("header").steps, 1000);
        std::fs::remove_file(&path).ok();
    }

    #[test]
    fn other_specs_versions_and_non_checkpoints_are_refused() {
        let net = ActorCritic::new(
            Layout {
                state_width: 2,
                stages: 2,
                actions: 2,
            },
            &[4],
            1,
        )
        .expect("net");
        let path = temp("refuse.safetensors");
        Checkpoint::save(&net, &header(&net), &path).expect("save");
        let err = Checkpoint::load(&path, "ffff", "grasp-sim/test")
            .expect_err("spec")
            .to_string();
        assert!(err.contains("trained with crm spec abc123"), "{err}");
        let err = Checkpoint::load(&path, "abc123", "grasp-sim/other")
            .expect_err("env")
            .to_string();
        assert!(
            err.contains("trained in environment grasp-sim/test"),
            "{err}"
        );

        let junk = temp("junk.safetensors");
        std::fs::write(&junk, b"this is not a checkpoint").expect("write");
        let err = Checkpoint::read_header(&junk)
            .expect_err("junk")
            .to_string();
        assert!(err.contains("not a safetensors file"), "{err}");
        let bare = temp("bare.safetensors");
        let tensors: Vec<_> = named(net.params()).collect();
        safetensors::serialize_to_file(tensors, None, &bare).expect("write");
        let err = Checkpoint::read_header(&bare)
            .expect_err("bare")
            .to_string();
        assert!(err.contains("without a crm-grasp header"), "{err}");
        // A network without its normalizer statistics (an older checkpoint) is refused.
        let stale = temp("stale.safetensors");
        Checkpoint::save_params(net.params(), &header(&net), &stale).expect("write");
        let err = Checkpoint::load(&stale, "abc123", "grasp-sim/test")
            .expect_err("no statistics")
            .to_string();
        assert!(
            err.contains("no observation-normalizer statistics"),
            "{err}"
        );
        for p in [path, junk, bare, stale] {
            std::fs::remove_file(p).ok();
        }
    }

    #[test]
    fn a_sac_checkpoint_keeps_its_observation_statistics_and_needs_them() {
        let layout = Layout {
            state_width: 4,
            stages: 3,
            actions: 5,
        };
        let mut nets = crate::sac::SacNets::new(layout, &[16, 16], 3).expect("nets");
        nets.update_norm(&[vec![1.0, 2.0], vec![3.0, -4.0, 0.5]], &[0, 2]);
        let header = CheckpointHeader {
            format: FORMAT.into(),
            algorithm: "crm-sac".into(),
            spec_hash: "abc123".into(),
            env_version: "grasp-sim/test".into(),
            seed: 3,
            steps: 10,
            layout,
            hidden: vec![16, 16],
            config: serde_json::json!({}),
            activation: None,
            world: None,
            world_hash: None,
            lineage: Vec::new(),
            state: None,
        };
        let path = temp("sac.safetensors");
        Checkpoint::save_sac(&nets, &header, &[], &path).expect("save");
        let (loaded, _) = Checkpoint::load_sac(&path, "abc123", "grasp-sim/test").expect("load");
        assert_eq!(loaded.norm(), nets.norm());
        let input = |n: &crate::sac::SacNets| -> Vec<f32> {
            n.input(&[vec![2.0, -1.0]], &[0])
                .and_then(|t| Ok(t.flatten_all()?.to_vec1::<f32>()?))
                .expect("input")
        };
        assert_eq!(input(&loaded), input(&nets), "the same normalized input");
        let stale = temp("sac-stale.safetensors");
        let relu = CheckpointHeader {
            activation: Some(SAC_ACTIVATION.into()),
            ..header.clone()
        };
        Checkpoint::save_params(&nets.params, &relu, &stale).expect("write");
        let err = Checkpoint::load_sac(&stale, "abc123", "grasp-sim/test")
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(
            err.contains("no observation-normalizer statistics"),
            "{err}"
        );
        // A checkpoint from before CRM-SAC's ReLU layers says nothing of them: refused.
        let tanh = temp("sac-tanh.safetensors");
        Checkpoint::save_normalized(&nets.params, nets.norm(), &header, &[], &tanh).expect("write");
        let err = Checkpoint::load_sac(&tanh, "abc123", "grasp-sim/test")
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(err.contains("tanh hidden layers"), "{err}");
        for p in [path, stale, tanh] {
            std::fs::remove_file(p).ok();
        }
    }
}
