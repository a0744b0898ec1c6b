//! `crm record`: replay evaluation episodes of a checkpoint into a rerun recording file, a
//! live viewer or a video (`--video out.mp4` or `.gif`, drawn by the software renderer);
//! `crm record --inspect FILE` says what a recording holds.

use std::path::PathBuf;

use anyhow::{Context, bail};
use crm_api::{EvalSpec, RecordSpec};

use super::{EnvArgs, emit};
use crate::record::{Recorder, Target, inspect, lock, reachable};
use crate::video::{self, VideoRecorder};
use crm_run::eval::evaluate;

#[derive(clap::Args, Debug)]
pub struct RecordArgs {
    #[command(flatten)]
    pub env: EnvArgs,
    /// The checkpoint whose policy acts (deterministically).
    #[arg(long, required_unless_present = "inspect")]
    pub checkpoint: Option<PathBuf>,
    /// The task (id); a random one from the seed when absent.
    #[arg(long)]
    pub task: Option<String>,
    /// Seed of the episode (task draw, randomization), as `crm eval --seed`.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Grasp topology: `task`, `auto` or a topology name.
    #[arg(long)]
    pub topology: Option<String>,
    /// Write the recording here (`.rrd`; open with `rerun FILE`).
    #[arg(long, conflicts_with = "connect", required_unless_present_any = ["connect", "inspect", "video"])]
    pub out: Option<PathBuf>,
    /// Write a video of the episodes here: `.mp4` (H.264, through ffmpeg) or `.gif`.
    #[arg(long, value_name = "FILE")]
    pub video: Option<PathBuf>,
    /// Episodes to record, one after another, drawn from `--seed` as `crm eval` draws them
    /// (at most 50: a video's frames are held in memory until it is written, 230 kB each at
    /// 320 x 240).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..=50))]
    pub episodes: u64,
    /// The video's frame size, WIDTHxHEIGHT.
    #[arg(long, default_value = "320x240", value_parser = crate::video::parse_size)]
    pub size: (u32, u32),
    /// Stream to a running viewer instead (`rerun+http://127.0.0.1:9876/proxy`).
    #[arg(long)]
    pub connect: Option<String>,
    /// Print what a recording file holds (JSON) instead of recording.
    #[arg(long, value_name = "FILE", conflicts_with_all = ["checkpoint", "out", "connect", "video"])]
    pub inspect: Option<PathBuf>,
}

pub fn run(args: RecordArgs) -> anyhow::Result<()> {
    if let Some(path) = &args.inspect {
        let summary = inspect::summarize(path)?;
        return emit(&format!("{}\n", serde_json::to_string_pretty(&summary)?));
    }
    let checkpoint = args
        .checkpoint
        .clone()
        .context("--checkpoint is required")?;
    if let Some(url) = &args.connect {
        reachable(url).map_err(|why| anyhow::anyhow!("--connect: {why}"))?;
    }
    for (flag, path) in [("--out", &args.out), ("--video", &args.video)] {
        if let Some(path) = path
            && path.is_dir()
        {
            bail!("{flag}: {} is a folder; give a file name", path.display());
        }
    }
    if let Some(video) = &args.video {
        video::Format::of(video).map_err(|e| anyhow::anyhow!("--video: {e}"))?;
    }
    let record = RecordSpec {
        every: 1,
        max_episodes: args.episodes,
        connect: args.connect.clone(),
    };
    let name = checkpoint
        .file_name()
        .map_or("checkpoint".into(), |n| n.to_string_lossy().to_string());
    let rerun = (args.out.is_some() || args.connect.is_some())
        .then(|| Recorder::new(&record, name).shared());
    if let Some(recorder) = &rerun
        && *lock(recorder).target() == Target::Off
    {
        bail!("--connect: the viewer stopped answering");
    }
    let video = args
        .video
        .as_ref()
        .map(|_| VideoRecorder::new(args.episodes, args.size).shared());
    let mut recorders: Vec<crm_run::SharedRecorder> = Vec::new();
    if let Some(r) = &rerun {
        recorders.push(r.clone());
    }
    if let Some(v) = &video {
        recorders.push(v.clone());
    }
    let recorder: crm_run::SharedRecorder = if recorders.len() == 1 {
        recorders.remove(0)
    } else {
        std::sync::Arc::new(std::sync::Mutex::new(crm_run::record::Tee(recorders)))
    };
    let spec = EvalSpec {
        world: None,
        episodes: args.episodes,
        seed: args.seed,
        task: args.task.clone(),
        tasks: Vec::new(),
        topology: args.topology.clone(),
        record: Some(record),
        video: None,
        objective: args.env.protocol,
        deterministic: false,
        hold_s: args.env.hold_s,
    };
    let mut episodes = Vec::new();
    evaluate(
        &checkpoint,
        &spec,
        args.env.env(),
        Some(recorder),
        |_, _, e| {
            episodes.push(e.clone());
            true
        },
    )?;
    let episode = episodes.first().context("no episode ran")?;
    let bytes = rerun.as_ref().and_then(|r| lock(r).take_pending());
    let written = match (&args.out, bytes) {
        (Some(out), Some((bytes, _))) => {
            let partial = out.with_extension("rrd.partial");
            std::fs::write(&partial, &bytes)
                .with_context(|| format!("writing {}", partial.display()))?;
            std::fs::rename(&partial, out).with_context(|| format!("writing {}", out.display()))?;
            bytes.len()
        }
        _ => 0,
    };
    let video_written = match (&args.video, &video) {
        (Some(path), Some(video)) => {
            let (frames, first) = {
                let mut video = video::lock(video);
                (video.take_frames(), video.first)
            };
            video::write(&frames, path).map_err(|e| anyhow::anyhow!("--video: {e}"))?;
            Some(serde_json::json!({
                "file": path.display().to_string(),
                "frames": frames.len(),
                "width": args.size.0,
                "height": args.size.1,
                "fps": video::FPS,
                "first_frame": first,
            }))
        }
        _ => None,
    };
    let report = serde_json::json!({
        "task": episode.task,
        "success": episode.success,
        "length": episode.length,
        "transitions": episode.transitions.iter().map(|(step, from, to, event, reward)| {
            serde_json::json!({"step": step, "from": from, "to": to, "event": event, "reward": reward})
        }).collect::<Vec<_>>(),
        "episodes": episodes.iter().map(|e| serde_json::json!({
            "task": e.task, "success": e.success, "length": e.length,
        })).collect::<Vec<_>>(),
        "out": args.out.as_ref().map(|p| p.display().to_string()),
        "connect": args.connect,
        "bytes": written,
        "video": video_written,
    });
    emit(&format!("{report}\n"))
}
