//! What a job records for the rerun viewer: every Nth episode (of environment 0 in training),
//! into a `.rrd` file stored with the job, or streamed live to a viewer. Off by default. And
//! an evaluation's video of its first episodes ([`VideoSpec`]), also off by default.

use serde::{Deserialize, Serialize};

use crate::config::ConfigError;

/// Recording settings of a job (`"record": {"every": 10}` in the job's JSON).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RecordSpec {
    /// Record every Nth episode: the 1st, the (N+1)th, ... In training only environment 0's
    /// episodes count, so the others never pay for logging. 0 turns recording off.
    #[serde(default = "default_every")]
    pub every: u64,
    /// Stop after this many recorded episodes, which bounds the file and a live viewer's
    /// memory over a long run.
    #[serde(default = "default_max_episodes")]
    pub max_episodes: u64,
    /// A viewer to stream to instead of the file, as the viewer prints it
    /// (`rerun+http://127.0.0.1:9876/proxy`). An unreachable viewer does not fail the job:
    /// the worker logs it and goes on without streaming.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub connect: Option<String>,
}

fn default_every() -> u64 {
    1
}

fn default_max_episodes() -> u64 {
    20
}

/// Most episodes one job may record.
pub const MAX_RECORDED_EPISODES: u64 = 1000;

impl Default for RecordSpec {
    fn default() -> Self {
        Self {
            every: default_every(),
            max_episodes: default_max_episodes(),
            connect: None,
        }
    }
}

impl RecordSpec {
    /// Whether this spec records anything.
    pub fn enabled(&self) -> bool {
        self.every > 0 && self.max_episodes > 0
    }

    /// Checks the fields; errors name the field inside `record`.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if self.max_episodes > MAX_RECORDED_EPISODES {
            return Err(ConfigError {
                field: "max_episodes",
                message: format!("must be at most {MAX_RECORDED_EPISODES}"),
            });
        }
        if let Some(url) = &self.connect {
            viewer_address(url).map_err(|message| ConfigError {
                field: "connect",
                message,
            })?;
        }
        Ok(())
    }
}

/// An evaluation's video (`"video": {"episodes": 3}`): its first episodes drawn by the
/// worker's software renderer into a GIF stored with the job, which the dashboard plays.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VideoSpec {
    /// Episodes shown, the evaluation's first.
    #[serde(default = "default_video_episodes")]
    pub episodes: u64,
    /// Frame size in pixels (`crm record --video`'s default 320 x 240).
    #[serde(default = "default_video_width")]
    pub width: u32,
    #[serde(default = "default_video_height")]
    pub height: u32,
}

fn default_video_episodes() -> u64 {
    3
}

fn default_video_width() -> u32 {
    320
}

fn default_video_height() -> u32 {
    240
}

/// Most episodes one evaluation's video shows: it is rendered and kept in memory before it is
/// encoded (a frame is 230 kB raw at 320 x 240; the GIF about 2 kB a frame: 1.19 MB for the
/// shipped model's first 10 episodes, 559 frames, `crm record --episodes 10 --video x.gif`).
pub const MAX_VIDEO_EPISODES: u64 = 10;

impl Default for VideoSpec {
    fn default() -> Self {
        Self {
            episodes: default_video_episodes(),
            width: default_video_width(),
            height: default_video_height(),
        }
    }
}

impl VideoSpec {
    /// Checks the fields; errors name the field inside `video`.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if self.episodes == 0 || self.episodes > MAX_VIDEO_EPISODES {
            return Err(ConfigError {
                field: "episodes",
                message: format!("must be between 1 and {MAX_VIDEO_EPISODES}"),
            });
        }
        for (field, value) in [("width", self.width), ("height", self.height)] {
            if !(16..=1280).contains(&value) || value % 2 != 0 {
                return Err(ConfigError {
                    field,
                    message: "must be an even number of pixels from 16 to 1280".into(),
                });
            }
        }
        Ok(())
    }
}

/// The `host:port` of a viewer URL (`rerun+http://HOST:PORT/proxy`, `rerun+https://...`,
/// `http://...`), or why it is not one.
pub fn viewer_address(url: &str) -> Result<String, String> {
    let rest = [
        "rerun+http://",
        "rerun+https://",
        "rerun://",
        "http://",
        "https://",
    ]
    .iter()
    .find_map(|scheme| url.strip_prefix(scheme))
    .ok_or_else(|| format!("{url:?} is not a viewer URL like rerun+http://127.0.0.1:9876/proxy"))?;
    let host_port = rest.split('/').next().unwrap_or_default();
    let (host, port) = host_port
        .rsplit_once(':')
        .ok_or_else(|| format!("{url:?} names no port"))?;
    // The port as the OpenAPI document's pattern has it: 1 to 65535, digits only, no
    // leading zero.
    let digits = port.bytes().all(|b| b.is_ascii_digit()) && !port.starts_with('0');
    if host.is_empty() || !digits || port.parse::<u16>().is_err() {
        return Err(format!("{url:?}: bad host or port"));
    }
    Ok(host_port.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_video_asks_one_to_ten_episodes_of_an_even_size() {
        let spec: VideoSpec = serde_json::from_str("{}").expect("spec");
        assert_eq!(spec, VideoSpec::default());
        assert_eq!(spec.validate(), Ok(()));
        for (bad, field) in [
            (r#"{"episodes": 0}"#, "episodes"),
            (r#"{"episodes": 11}"#, "episodes"),
            (r#"{"width": 321}"#, "width"),
            (r#"{"height": 4000}"#, "height"),
        ] {
            let spec: VideoSpec = serde_json::from_str(bad).expect("spec");
            assert_eq!(spec.validate().map_err(|e| e.field), Err(field), "{bad}");
        }
        assert!(serde_json::from_str::<VideoSpec>(r#"{"fps": 30}"#).is_err());
    }

    #[test]
    fn defaults_record_every_episode_up_to_twenty() {
        let spec: RecordSpec = serde_json::from_str("{}").expect("spec");
        assert_eq!(spec, RecordSpec::default());
        assert!(spec.enabled());
        assert!(!RecordSpec { every: 0, ..spec }.enabled());
    }

    #[test]
    fn viewer_urls_are_checked() {
        assert_eq!(
            viewer_address("rerun+http://127.0.0.1:9876/proxy").as_deref(),
            Ok("127.0.0.1:9876")
        );
        assert!(viewer_address("ftp://x:1").is_err());
        assert!(viewer_address("rerun+http://host/proxy").is_err());
        assert!(viewer_address("rerun+http://:9876/proxy").is_err());
        let bad = RecordSpec {
            connect: Some("nowhere".into()),
            ..RecordSpec::default()
        };
        assert_eq!(bad.validate().expect_err("bad url").field, "connect");
        let many = RecordSpec {
            max_episodes: 5000,
            ..RecordSpec::default()
        };
        assert_eq!(many.validate().expect_err("too many").field, "max_episodes");
    }
}
