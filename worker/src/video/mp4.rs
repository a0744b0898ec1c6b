//! MP4 (H.264, yuv420p, `+faststart` so it plays while it downloads): raw RGB frames piped
//! into the `ffmpeg` program, as gymnasium's `RecordVideo` does (through moviepy and
//! imageio-ffmpeg). `CRM_FFMPEG` names the program when it is not `ffmpeg` on the `PATH`.
//! No H.264 encoder is linked into `crm`: GIF needs none.

use std::io::Write;
use std::path::Path;
use std::process::{Command, Stdio};

use anyhow::{Context, bail};
use grasp_sim::render::Frame;

/// The ffmpeg program: `CRM_FFMPEG`, else `ffmpeg`.
pub fn program() -> String {
    std::env::var("CRM_FFMPEG").unwrap_or_else(|_| "ffmpeg".into())
}

/// Writes `frames` to `out` as an MP4 at `fps` frames a second.
pub fn write(frames: &[Frame], fps: u32, out: &Path) -> anyhow::Result<()> {
    let first = frames.first().context("a video needs at least one frame")?;
    if first.width % 2 != 0 || first.height % 2 != 0 {
        bail!(
            "MP4 (yuv420p) needs an even width and height, not {}x{}",
            first.width,
            first.height
        );
    }
    let ffmpeg = program();
    let mut child = Command::new(&ffmpeg)
        .args(["-hide_banner", "-loglevel", "error", "-y", "-f", "rawvideo"])
        .args(["-pix_fmt", "rgb24", "-s"])
        .arg(format!("{}x{}", first.width, first.height))
        .args([
            "-r",
            &fps.to_string(),
            "-i",
            "pipe:0",
            "-an",
            "-c:v",
            "libx264",
        ])
        .args([
            "-pix_fmt",
            "yuv420p",
            "-crf",
            "20",
            "-movflags",
            "+faststart",
        ])
        .args(["-f", "mp4"])
        .arg(out)
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| {
            anyhow::anyhow!(
                "writing {} needs ffmpeg ({ffmpeg}: {e}); install it (Debian: apt-get install \
                 ffmpeg), name it with CRM_FFMPEG, or write a .gif, which needs nothing",
                out.display()
            )
        })?;
    let mut stdin = child.stdin.take().context("ffmpeg's input")?;
    let fed = frames.iter().try_for_each(|frame| {
        if (frame.width, frame.height) != (first.width, first.height) {
            return Err(std::io::Error::other("frames of one video differ in size"));
        }
        stdin.write_all(&frame.rgb)
    });
    drop(stdin);
    let output = child.wait_with_output().context("waiting for ffmpeg")?;
    if !output.status.success() {
        bail!(
            "{ffmpeg} could not write {}: {}",
            out.display(),
            String::from_utf8_lossy(&output.stderr).trim()
        );
    }
    fed.with_context(|| format!("feeding frames to {ffmpeg}"))
}
