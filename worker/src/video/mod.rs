//! Videos of episodes (`crm record --video`, an evaluation job's attached video): a
//! [`VideoRecorder`] follows the first episodes the runtime runs (through the same
//! `Recorder`/`EpisodeLog` traits the rerun recorder implements), renders the scene the
//! recording draws on every control step with the software renderer
//! ([`grasp_sim::render`]: hand, object, table, the grasp location; the task, stage and
//! step as a caption, the outcome held on the last frame), and writes the frames as GIF
//! (`gif.rs`) or MP4 (`mp4.rs`, through ffmpeg).

mod gif;
pub mod mp4;

use std::any::Any;
use std::path::Path;
use std::sync::{Arc, Mutex};

use anyhow::bail;
use crm_api::Iteration;
use crm_run::eval::EpisodeRecord;
use crm_run::record::{EpisodeLog, Move};
use grasp_sim::render::{Camera, Frame, render};

/// Frames a second: one a control step (the world steps at 30 Hz).
pub const FPS: u32 = 30;
/// How long the last frame of an episode is held (frames), so its outcome can be read.
const HOLD_FRAMES: usize = 15;

/// Caption colours.
const WHITE: [u8; 3] = [255, 255, 255];
const GREEN: [u8; 3] = [90, 230, 90];
const RED: [u8; 3] = [255, 90, 80];

/// A video file's format, from its extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    Gif,
    Mp4,
}

impl Format {
    pub fn of(path: &Path) -> anyhow::Result<Self> {
        match path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase)
        {
            Some(e) if e == "gif" => Ok(Format::Gif),
            Some(e) if e == "mp4" => Ok(Format::Mp4),
            _ => bail!(
                "{}: a video is written as .mp4 or .gif (by its extension)",
                path.display()
            ),
        }
    }
}

/// Writes `frames` to `path` in the format its extension names.
pub fn write(frames: &[Frame], path: &Path) -> anyhow::Result<()> {
    match Format::of(path)? {
        Format::Gif => {
            let partial = path.with_extension("gif.partial");
            let file = std::fs::File::create(&partial)
                .map_err(|e| anyhow::anyhow!("writing {}: {e}", partial.display()))?;
            gif::write(frames, FPS, std::io::BufWriter::new(file))?;
            std::fs::rename(&partial, path)
                .map_err(|e| anyhow::anyhow!("writing {}: {e}", path.display()))
        }
        Format::Mp4 => mp4::write(frames, FPS, path),
    }
}

/// `frames` as GIF bytes (an evaluation job's upload).
pub fn gif_bytes(frames: &[Frame]) -> anyhow::Result<Vec<u8>> {
    let mut out = Vec::new();
    gif::write(frames, FPS, &mut out)?;
    Ok(out)
}

/// Parses `WIDTHxHEIGHT`.
pub fn parse_size(text: &str) -> Result<(u32, u32), String> {
    let (w, h) = text
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("{text:?}: give WIDTHxHEIGHT, such as 320x240"))?;
    let parse = |s: &str| {
        s.trim()
            .parse::<u32>()
            .ok()
            .filter(|v| (16..=4096).contains(v))
    };
    match (parse(w), parse(h)) {
        (Some(w), Some(h)) => Ok((w, h)),
        _ => Err(format!("{text:?}: width and height are 16 to 4096 pixels")),
    }
}

/// Where the object (its parts' mean position) and the palm land in
/// the first frame, in pixels: what a test or a caller checks the picture against.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Landmarks {
    pub object: Option<[f32; 2]>,
    pub palm: Option<[f32; 2]>,
}

/// Follows the first `episodes` episodes and keeps their frames.
pub struct VideoRecorder {
    episodes: u64,
    seen: u64,
    size: (u32, u32),
    frames: Vec<Frame>,
    /// The followed episodes that ended (for a caller's report).
    pub ended: u64,
    /// The first frame's landmarks.
    pub first: Option<Landmarks>,
}

/// A shared video recorder.
pub type SharedVideo = Arc<Mutex<VideoRecorder>>;

impl VideoRecorder {
    pub fn new(episodes: u64, size: (u32, u32)) -> Self {
        VideoRecorder {
            episodes,
            seen: 0,
            size,
            frames: Vec::new(),
            ended: 0,
            first: None,
        }
    }

    pub fn shared(self) -> SharedVideo {
        Arc::new(Mutex::new(self))
    }

    /// The frames so far, taken out.
    pub fn take_frames(&mut self) -> Vec<Frame> {
        std::mem::take(&mut self.frames)
    }
}

/// Locks a shared video recorder; a poisoned lock still holds usable frames.
pub fn lock(video: &SharedVideo) -> std::sync::MutexGuard<'_, VideoRecorder> {
    video.lock().unwrap_or_else(|e| e.into_inner())
}

struct VideoLog {
    what: String,
    size: (u32, u32),
    camera: Option<Camera>,
    stage: String,
    frames: Vec<Frame>,
    first: Option<Landmarks>,
}

impl VideoLog {
    fn draw(&mut self, env: &grasp_sim::GraspEnv, step: i64) {
        let parts = env.parts();
        let camera = self
            .camera
            .get_or_insert_with(|| Camera::on_scene(&parts, self.size.0, self.size.1));
        let mut frame = render(&parts, env.grasp_location().map(Into::into), camera);
        if self.first.is_none() {
            let palm = parts.iter().find(|p| p.name == "hand/palm");
            let object: Vec<&grasp_sim::view::Part> = parts
                .iter()
                .filter(|p| p.name.starts_with("object"))
                .collect();
            let mut centre = [0.0f32; 3];
            for p in &object {
                for (c, x) in centre.iter_mut().zip(p.translation) {
                    *c += x / object.len() as f32;
                }
            }
            self.first = Some(Landmarks {
                object: (!object.is_empty())
                    .then(|| camera.project(centre))
                    .flatten(),
                palm: palm.and_then(|p| camera.project(p.translation)),
            });
        }
        let stage = format!("{}  step {step}", self.stage);
        frame.caption(&[(&self.what, WHITE), (&stage, WHITE)]);
        self.frames.push(frame);
    }
}

impl crm_run::record::Recorder for VideoRecorder {
    fn begin_episode(&mut self, what: &str) -> Option<Box<dyn EpisodeLog>> {
        self.seen += 1;
        (self.seen <= self.episodes).then(|| {
            Box::new(VideoLog {
                what: what.to_string(),
                size: self.size,
                camera: None,
                stage: String::new(),
                frames: Vec::new(),
                first: None,
            }) as Box<dyn EpisodeLog>
        })
    }

    fn end_episode(&mut self, log: Box<dyn EpisodeLog>, summary: Option<EpisodeRecord>) {
        if let Ok(log) = (log as Box<dyn Any>).downcast::<VideoLog>() {
            self.frames.extend(log.frames);
            self.first = self.first.or(log.first);
            self.ended += u64::from(summary.is_some());
        }
    }

    fn log_iteration(&mut self, _: &Iteration) {}
}

impl EpisodeLog for VideoLog {
    fn start(&mut self, env: &grasp_sim::GraspEnv, stage: &str, _: crm::StageId) {
        self.stage = stage.to_string();
        self.draw(env, 0);
    }

    fn step(&mut self, step: i64, env: &grasp_sim::GraspEnv, moved: Option<Move<'_>>) {
        if let Some(moved) = moved {
            self.stage = moved.to.to_string();
        }
        self.draw(env, step);
    }

    fn end(&mut self, stage: &str, steps: i64, truncated: bool) {
        let Some(last) = self.frames.last() else {
            return;
        };
        let mut last = last.clone();
        let (text, color) = match (stage, truncated) {
            ("success", false) => (format!("SUCCESS after {steps} steps"), GREEN),
            (_, true) => (format!("CUT SHORT in {stage} after {steps} steps"), RED),
            _ => (format!("FAILED: {stage} after {steps} steps"), RED),
        };
        last.caption(&[(&self.what, WHITE), (&text, color)]);
        let n = self.frames.len();
        self.frames[n - 1] = last.clone();
        self.frames.extend(std::iter::repeat_n(last, HOLD_FRAMES));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_and_formats_are_read_or_refused_with_the_reason() {
        assert_eq!(parse_size("320x240"), Ok((320, 240)));
        assert!(parse_size("320").unwrap_err().contains("WIDTHxHEIGHT"));
        assert!(parse_size("8x8").unwrap_err().contains("16 to 4096"));
        assert_eq!(Format::of(Path::new("a/b.MP4")).unwrap(), Format::Mp4);
        assert_eq!(Format::of(Path::new("b.gif")).unwrap(), Format::Gif);
        let err = Format::of(Path::new("b.avi")).unwrap_err().to_string();
        assert!(err.contains(".mp4 or .gif"), "{err}");
    }
}
