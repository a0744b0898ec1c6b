//! TensorBoard event files of a training run, so that it sits beside a lab's other runs
//! (`tensorboard --logdir runs`, W&B's `sync_tensorboard`): every series of an iteration as a
//! scalar by environment step, and the run's settings as text and as hyperparameters
//! ([`hparams`]). The format is TensorFlow's
//! `Event` protocol buffer (`tensorflow/core/util/event.proto`, the messages below, encoded with
//! prost) in TFRecord framing: each record is its length (u64, little-endian), the masked
//! CRC32C of the length, the data and the masked CRC32C of the data. No crate for it is kept up
//! (`tensorboard-rs` last released in 2020, `tfrecord` generates its messages with `protoc`), so
//! the framing is written here, with the `crc` crate's CRC-32C (Castagnoli, `CRC_32_ISCSI`).

pub mod hparams;

use std::io::Write;

use crate::Iteration;

/// TensorFlow's `Event`, the fields written here.
#[derive(Clone, PartialEq, prost::Message)]
pub struct Event {
    #[prost(double, tag = "1")]
    pub wall_time: f64,
    #[prost(int64, tag = "2")]
    pub step: i64,
    #[prost(string, optional, tag = "3")]
    pub file_version: Option<String>,
    #[prost(message, optional, tag = "5")]
    pub summary: Option<Summary>,
}

/// TensorFlow's `Summary`.
#[derive(Clone, PartialEq, prost::Message)]
pub struct Summary {
    #[prost(message, repeated, tag = "1")]
    pub value: Vec<Value>,
}

/// `Summary.Value`: a scalar (`simple_value`) or a tensor with its plugin's metadata.
#[derive(Clone, PartialEq, prost::Message)]
pub struct Value {
    #[prost(string, tag = "1")]
    pub tag: String,
    #[prost(float, optional, tag = "2")]
    pub simple_value: Option<f32>,
    #[prost(message, optional, tag = "8")]
    pub tensor: Option<TensorProto>,
    #[prost(message, optional, tag = "9")]
    pub metadata: Option<SummaryMetadata>,
}

/// `SummaryMetadata`: which plugin reads the value.
#[derive(Clone, PartialEq, prost::Message)]
pub struct SummaryMetadata {
    #[prost(message, optional, tag = "1")]
    pub plugin_data: Option<PluginData>,
}

/// `SummaryMetadata.PluginData`.
#[derive(Clone, PartialEq, prost::Message)]
pub struct PluginData {
    #[prost(string, tag = "1")]
    pub plugin_name: String,
    #[prost(bytes = "vec", tag = "2")]
    pub content: Vec<u8>,
}

/// `TensorProto`, as a text summary's: a scalar string tensor.
#[derive(Clone, PartialEq, prost::Message)]
pub struct TensorProto {
    /// `DataType`: 7 is `DT_STRING`.
    #[prost(int32, tag = "1")]
    pub dtype: i32,
    #[prost(message, optional, tag = "2")]
    pub tensor_shape: Option<TensorShape>,
    #[prost(bytes = "vec", repeated, tag = "8")]
    pub string_val: Vec<Vec<u8>>,
}

/// `TensorShapeProto` (a scalar: no dimensions).
#[derive(Clone, PartialEq, prost::Message)]
pub struct TensorShape {}

const DT_STRING: i32 = 7;
const CRC32C: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISCSI);

/// TFRecord's masked CRC32C.
pub fn masked_crc(data: &[u8]) -> u32 {
    let crc = CRC32C.checksum(data);
    crc.rotate_right(15).wrapping_add(0xa282_ead8)
}

/// One record: length, its masked CRC, the data, its masked CRC.
pub fn record(data: &[u8]) -> Vec<u8> {
    let length = (data.len() as u64).to_le_bytes();
    let mut out = Vec::with_capacity(data.len() + 16);
    out.extend_from_slice(&length);
    out.extend_from_slice(&masked_crc(&length).to_le_bytes());
    out.extend_from_slice(data);
    out.extend_from_slice(&masked_crc(data).to_le_bytes());
    out
}

fn encode(event: &Event) -> Vec<u8> {
    record(&prost::Message::encode_to_vec(event))
}

/// The first record of every event file.
pub fn header(wall_time: f64) -> Vec<u8> {
    encode(&Event {
        wall_time,
        step: 0,
        file_version: Some("brain.Event:2".into()),
        summary: None,
    })
}

/// A text summary (TensorBoard's text plugin renders it as Markdown).
pub fn text(tag: &str, markdown: &str, step: u64, wall_time: f64) -> Vec<u8> {
    encode(&Event {
        wall_time,
        step: step as i64,
        file_version: None,
        summary: Some(Summary {
            value: vec![Value {
                tag: tag.into(),
                simple_value: None,
                tensor: Some(TensorProto {
                    dtype: DT_STRING,
                    tensor_shape: Some(TensorShape {}),
                    string_val: vec![markdown.as_bytes().to_vec()],
                }),
                metadata: Some(SummaryMetadata {
                    plugin_data: Some(PluginData {
                        plugin_name: "text".into(),
                        content: Vec::new(),
                    }),
                }),
            }],
        }),
    })
}

/// An iteration's series as (tag, value): the dashboard's charts and the rest of `Iteration`,
/// the stage mix and the per-task success as `stage_mix/STAGE` and `task_success/TASK`.
pub fn scalars(it: &Iteration) -> Vec<(String, f64)> {
    let mut out: Vec<(String, f64)> = [
        (
            "train/success_rate_last_100",
            Some(it.success_rate_last_100),
        ),
        ("train/episodes", Some(it.episodes as f64)),
        ("train/successes", Some(it.successes as f64)),
        ("train/mean_return", it.mean_return),
        ("train/mean_intra_return", it.mean_intra_return),
        ("train/mean_transition_return", it.mean_transition_return),
        ("train/mean_episode_length", it.mean_episode_length),
        ("losses/policy_loss", Some(it.policy_loss)),
        ("losses/value_loss", Some(it.value_loss)),
        ("losses/entropy", Some(it.entropy)),
        ("losses/approx_kl", Some(it.approx_kl)),
        ("losses/clipfrac", Some(it.clipfrac)),
        ("charts/learning_rate", Some(it.learning_rate)),
        ("charts/steps_per_s", Some(it.steps_per_s)),
    ]
    .into_iter()
    .filter_map(|(tag, value)| value.map(|v| (tag.to_string(), v)))
    .collect();
    out.extend(
        it.stage_mix
            .iter()
            .map(|(stage, share)| (format!("stage_mix/{stage}"), *share)),
    );
    out.extend(
        it.task_success
            .iter()
            .map(|(task, rate)| (format!("task_success/{task}"), *rate)),
    );
    out
}

/// An iteration's scalars as one event at its environment step.
pub fn iteration(it: &Iteration, wall_time: f64) -> Vec<u8> {
    encode(&Event {
        wall_time,
        step: it.steps as i64,
        file_version: None,
        summary: Some(Summary {
            value: scalars(it)
                .into_iter()
                .map(|(tag, value)| Value {
                    tag,
                    simple_value: Some(value as f32),
                    tensor: None,
                    metadata: None,
                })
                .collect(),
        }),
    })
}

/// A whole event file: the header, the run's settings as text (`settings`, JSON shown as a
/// code block) and as hyperparameters (`hparams`), and every iteration; `start` is the run's start (Unix seconds), each iteration
/// stamped `start + wall_s`.
pub fn file(settings: &serde_json::Value, iterations: &[Iteration], start: f64) -> Vec<u8> {
    let mut out = header(start);
    out.extend(settings_text(settings, start));
    out.extend(hparams::session_start(settings, start));
    for it in iterations {
        out.extend(iteration(it, start + it.wall_s));
    }
    out
}

/// The settings as a text summary at step 0.
pub fn settings_text(settings: &serde_json::Value, start: f64) -> Vec<u8> {
    let pretty = serde_json::to_string_pretty(settings).unwrap_or_default();
    text("settings", &format!("```\n{pretty}\n```"), 0, start)
}

/// Appends records to an event file as a run goes (`crm train`).
pub struct Writer<W: Write> {
    out: W,
    start: f64,
}

impl<W: Write> Writer<W> {
    /// A new file's writer: writes the header and the settings.
    pub fn new(mut out: W, settings: &serde_json::Value, start: f64) -> std::io::Result<Self> {
        out.write_all(&header(start))?;
        out.write_all(&settings_text(settings, start))?;
        out.write_all(&hparams::session_start(settings, start))?;
        out.flush()?;
        Ok(Self { out, start })
    }

    /// One iteration, flushed (TensorBoard reads the file while it grows).
    pub fn iteration(&mut self, it: &Iteration) -> std::io::Result<()> {
        self.out.write_all(&iteration(it, self.start + it.wall_s))?;
        self.out.flush()
    }
}

/// The file name TensorBoard looks for: `events.out.tfevents.SECONDS.HOST`.
pub fn file_name(start: f64, host: &str) -> String {
    format!("events.out.tfevents.{}.{host}", start as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_framing_is_tfrecords() {
        // CRC-32C of "123456789" is 0xE3069283 (the check value of CRC_32_ISCSI).
        assert_eq!(CRC32C.checksum(b"123456789"), 0xE306_9283);
        let data = b"hello";
        let framed = record(data);
        assert_eq!(framed.len(), 8 + 4 + 5 + 4);
        assert_eq!(&framed[..8], &5u64.to_le_bytes());
        assert_eq!(&framed[12..17], data);
        let masked = u32::from_le_bytes(framed[17..].try_into().expect("4 bytes"));
        let crc = CRC32C.checksum(data);
        // TFRecord's mask as its format spells it.
        #[allow(clippy::manual_rotate)]
        let spelled = ((crc >> 15) | (crc << 17)).wrapping_add(0xa282_ead8);
        assert_eq!(masked, spelled);
        let framed = encode(&Event {
            wall_time: 1.5,
            step: 7,
            file_version: None,
            summary: None,
        });
        let n = u64::from_le_bytes(framed[..8].try_into().expect("8 bytes")) as usize;
        let event: Event = prost::Message::decode(&framed[12..12 + n]).expect("decode");
        assert_eq!((event.wall_time, event.step), (1.5, 7));
    }
}
