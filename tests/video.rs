//! Videos end to end: `crm record --video` writes a GIF and an MP4 (through the real ffmpeg)
//! of the shipped model's episodes whose decoded frames have the size and count the command
//! reports and show the object and the palm where the scene puts them; an evaluation job that
//! asks for a video stores it with the job (downloadable over REST, listed in the run and
//! evaluation views); bad settings are refused naming the field. The dashboard playing it is
//! `web/tests/dashboard.mjs`'s (tests/web.rs).

mod support;

use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::{Value, json};
use support::{TempDir, crm, get, http, start_server, start_worker, wait_state};

fn model() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/crm-ppo.safetensors")
}

/// The ffmpeg program the tests decode with (`CRM_FFMPEG`, else `ffmpeg`).
fn ffmpeg() -> String {
    std::env::var("CRM_FFMPEG").unwrap_or_else(|_| "ffmpeg".into())
}

/// A GIF's frames as RGB, with their size.
fn decode_gif(bytes: &[u8]) -> Vec<(u16, u16, Vec<u8>)> {
    let mut options = gif::DecodeOptions::new();
    options.set_color_output(gif::ColorOutput::RGBA);
    let mut decoder = options.read_info(bytes).expect("a GIF");
    let mut frames = Vec::new();
    while let Some(frame) = decoder.read_next_frame().expect("a frame") {
        let rgb = frame
            .buffer
            .chunks(4)
            .flat_map(|p| [p[0], p[1], p[2]])
            .collect();
        frames.push((frame.width, frame.height, rgb));
    }
    frames
}

/// An MP4's frames as RGB, decoded by ffmpeg.
fn decode_mp4(path: &Path, width: usize, height: usize) -> Vec<Vec<u8>> {
    let out = Command::new(ffmpeg())
        .args(["-hide_banner", "-loglevel", "error", "-i"])
        .arg(path)
        .args(["-f", "rawvideo", "-pix_fmt", "rgb24", "pipe:1"])
        .output()
        .unwrap_or_else(|e| {
            panic!(
                "{}: {e} (the tests need ffmpeg: apt-get install ffmpeg)",
                ffmpeg()
            )
        });
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let size = width * height * 3;
    assert_eq!(out.stdout.len() % size, 0);
    out.stdout.chunks(size).map(<[u8]>::to_vec).collect()
}

fn pixel(rgb: &[u8], width: usize, at: [f64; 2]) -> [i32; 3] {
    let (x, y) = (at[0].round() as usize, at[1].round() as usize);
    let i = 3 * (y * width + x);
    [rgb[i].into(), rgb[i + 1].into(), rgb[i + 2].into()]
}

/// The object is drawn blue and the hand in warm skin tones (the rerun palette).
fn assert_scene(rgb: &[u8], width: usize, first: &Value, what: &str) {
    let at = |key: &str| -> [f64; 2] {
        let p = first[key]
            .as_array()
            .unwrap_or_else(|| panic!("{key}: {first}"));
        [p[0].as_f64().expect("x"), p[1].as_f64().expect("y")]
    };
    let [r, g, b] = pixel(rgb, width, at("object"));
    assert!(
        b > r + 30 && b > g,
        "{what}: the object's pixel is {r} {g} {b}"
    );
    let [r, g, b] = pixel(rgb, width, at("palm"));
    assert!(
        r > b + 25 && r > 60,
        "{what}: the palm's pixel is {r} {g} {b}"
    );
}

fn record(args: &[&str]) -> std::process::Output {
    Command::new(crm())
        .args(["record", "--checkpoint"])
        .arg(model())
        .args(["--task", "valve-twist", "--seed", "1"])
        .args(args)
        .output()
        .expect("run crm record")
}

#[test]
fn crm_record_writes_gif_and_mp4_videos_that_show_the_scene() {
    let dir = TempDir::new("video-cli");
    let gif_path = dir.0.join("episodes.gif");
    let run = record(&[
        "--episodes",
        "2",
        "--video",
        gif_path.to_str().expect("path"),
    ]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let report: Value = serde_json::from_slice(&run.stdout).expect("JSON");
    let video = &report["video"];
    assert_eq!(
        (video["width"].as_u64(), video["height"].as_u64()),
        (Some(320), Some(240))
    );
    let episodes = report["episodes"].as_array().expect("episodes");
    assert_eq!(episodes.len(), 2);
    // One frame a control step and the first state, and the last frame held 15 more.
    let steps: u64 = episodes
        .iter()
        .map(|e| e["length"].as_u64().expect("length"))
        .sum();
    let frames = video["frames"].as_u64().expect("frames");
    assert_eq!(frames, steps + 2 * (1 + 15), "{report}");
    let gif = decode_gif(&std::fs::read(&gif_path).expect("the GIF"));
    assert_eq!(gif.len() as u64, frames);
    assert!(gif.iter().all(|(w, h, _)| (*w, *h) == (320, 240)));
    assert_scene(&gif[0].2, 320, &video["first_frame"], "GIF");
    // The hand moves: the first and the last frame of the first episode differ.
    assert_ne!(
        gif[0].2,
        gif[episodes[0]["length"].as_u64().expect("n") as usize].2
    );

    // The same episodes as MP4, through ffmpeg.
    let mp4_path = dir.0.join("episodes.mp4");
    let run = record(&[
        "--episodes",
        "2",
        "--video",
        mp4_path.to_str().expect("path"),
    ]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let mp4_report: Value = serde_json::from_slice(&run.stdout).expect("JSON");
    assert_eq!(mp4_report["video"]["frames"], frames);
    let decoded = decode_mp4(&mp4_path, 320, 240);
    assert_eq!(decoded.len() as u64, frames);
    assert_scene(&decoded[0], 320, &video["first_frame"], "MP4");

    // Bad input: exit code 2, a message naming the flag, nothing written.
    let avi = dir.0.join("x.avi");
    for (args, says) in [
        (vec!["--video", avi.to_str().expect("path")], ".mp4 or .gif"),
        (vec!["--video", "x.gif", "--size", "7x7"], "--size"),
        (vec!["--video", "x.gif", "--episodes", "0"], "--episodes"),
    ] {
        let run = record(&args);
        assert_eq!(run.status.code(), Some(2), "{args:?}");
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert!(stderr.contains(says), "{args:?}: {stderr}");
    }
    assert!(!avi.exists());
    // MP4 without ffmpeg: the message says what to do; no file is left.
    let missing = dir.0.join("missing.mp4");
    let run = Command::new(crm())
        .env("CRM_FFMPEG", dir.0.join("no-ffmpeg-here"))
        .args(["record", "--checkpoint"])
        .arg(model())
        .args(["--task", "valve-twist", "--video"])
        .arg(&missing)
        .output()
        .expect("run crm record");
    assert!(!run.status.success());
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(
        stderr.contains("needs ffmpeg") && stderr.contains(".gif"),
        "{stderr}"
    );
    assert!(!missing.exists());
}

#[test]
fn an_evaluation_job_stores_its_video_with_the_run() {
    let data = TempDir::new("video-jobs");
    let server = start_server(&data.0, &[]);
    let addr = server.http.clone();
    let _worker = start_worker(&format!("http://{}", server.grpc), &[]);
    let train = support::submit(
        &addr,
        &json!({"kind": "train", "algorithm": "crm-ppo", "task": "valve-twist", "steps": 2048,
                "envs": 2, "config": {"rollout_steps": 1024}})
        .to_string(),
    );
    let run_id = train["id"].as_i64().expect("id");
    let done = wait_state(&addr, run_id, "succeeded", 300);
    let checkpoint = done["result"]["checkpoint_id"]
        .as_i64()
        .expect("checkpoint");

    // Refused settings name the field, and nothing is queued.
    for (video, field) in [
        (json!({"episodes": 0}), "video.episodes"),
        (json!({"episodes": 11}), "video.episodes"),
        (json!({"width": 321}), "video.width"),
        (json!({"fps": 30}), "video"),
    ] {
        let body =
            json!({"kind": "eval", "checkpoint_id": checkpoint, "episodes": 3, "video": video});
        let reply = http(&addr, "POST", "/api/v1/jobs", Some(&body.to_string()), None);
        assert_eq!(reply.status, 400, "{video}");
        let error = reply.json();
        let named = error["error"]["field"].as_str().expect("field");
        assert!(named.starts_with(field), "{video}: {error}");
    }
    assert_eq!(
        get(&addr, "/api/v1/evaluations")["evaluations"]
            .as_array()
            .map(Vec::len),
        Some(0)
    );

    let eval = support::submit(
        &addr,
        &json!({"kind": "eval", "checkpoint_id": checkpoint, "episodes": 4, "task": "valve-twist",
                "video": {"episodes": 2, "width": 160, "height": 120}})
        .to_string(),
    );
    let eval_id = eval["id"].as_i64().expect("id");
    wait_state(&addr, eval_id, "succeeded", 300);
    let evaluation = get(&addr, &format!("/api/v1/evaluations/{eval_id}"));
    let video = &evaluation["video"];
    assert_eq!(video["episodes"], 2, "{evaluation}");
    assert_eq!(
        (video["width"].as_u64(), video["height"].as_u64()),
        (Some(160), Some(120))
    );
    let path = video["download"].as_str().expect("download");
    let reply = http(&addr, "GET", path, None, None);
    assert_eq!(reply.status, 200);
    assert_eq!(reply.header("content-type").as_deref(), Some("image/gif"));
    assert_eq!(
        reply.body.len() as u64,
        video["size"].as_u64().expect("size")
    );
    let frames = decode_gif(&reply.body);
    assert_eq!(
        frames.len() as u64,
        video["frames"].as_u64().expect("frames")
    );
    assert!(frames.iter().all(|(w, h, _)| (*w, *h) == (160, 120)));
    // The first two episodes' lengths (their summaries, stored in order) and their held ends.
    let episodes = evaluation["episodes"].as_array().expect("episodes");
    let lengths: u64 = episodes[..2]
        .iter()
        .map(|e| e["length"].as_u64().expect("length"))
        .sum();
    assert_eq!(frames.len() as u64, lengths + 2 * 16);

    // The run lists its evaluations' videos; a job without one answers 404 naming it.
    let run = get(&addr, &format!("/api/v1/runs/{run_id}"));
    assert_eq!(run["videos"][0]["job_id"], eval_id, "{}", run["videos"]);
    let none = http(
        &addr,
        "GET",
        &format!("/api/v1/jobs/{run_id}/video"),
        None,
        None,
    );
    assert_eq!(none.status, 404);
    assert!(
        none.json()["error"]["message"]
            .as_str()
            .expect("message")
            .contains("no video")
    );
}
