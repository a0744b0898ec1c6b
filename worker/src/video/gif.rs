//! GIF: every frame through one fixed palette of 6 x 7 x 6 levels (252 colours; the scene is
//! flat-shaded, so no per-frame quantizer is needed and the bytes are the same on every
//! run), encoded by the `gif` crate (image-rs's, pure Rust). Plays in every browser: the
//! dashboard shows an evaluation's video as a GIF.

use std::io::Write;

use anyhow::Context;
use grasp_sim::render::Frame;

const LEVELS: [u32; 3] = [6, 7, 6];

/// The palette: red slowest, blue fastest.
fn palette() -> Vec<u8> {
    let level = |k: u32, n: u32| (k * 255 / (n - 1)) as u8;
    let mut out = Vec::with_capacity(3 * 252);
    for r in 0..LEVELS[0] {
        for g in 0..LEVELS[1] {
            for b in 0..LEVELS[2] {
                out.extend([
                    level(r, LEVELS[0]),
                    level(g, LEVELS[1]),
                    level(b, LEVELS[2]),
                ]);
            }
        }
    }
    out
}

/// The palette index nearest `rgb` (per channel).
fn index(rgb: &[u8]) -> u8 {
    let q = |c: u8, n: u32| (u32::from(c) * (n - 1) + 127) / 255;
    let (r, g, b) = (
        q(rgb[0], LEVELS[0]),
        q(rgb[1], LEVELS[1]),
        q(rgb[2], LEVELS[2]),
    );
    ((r * LEVELS[1] + g) * LEVELS[2] + b) as u8
}

/// Writes `frames` (all one size) as a looping GIF at `fps` frames a second (GIF counts
/// delays in hundredths: 30 fps is written as 3/100 s).
pub fn write(frames: &[Frame], fps: u32, out: impl Write) -> anyhow::Result<()> {
    let first = frames.first().context("a video needs at least one frame")?;
    let (w, h) = (
        u16::try_from(first.width).context("GIF frames are at most 65535 wide")?,
        u16::try_from(first.height).context("GIF frames are at most 65535 high")?,
    );
    let mut encoder = gif::Encoder::new(out, w, h, &palette())?;
    encoder.set_repeat(gif::Repeat::Infinite)?;
    let delay = (100 / fps.max(1)).max(2) as u16;
    for frame in frames {
        anyhow::ensure!(
            (frame.width, frame.height) == (first.width, first.height),
            "frames of one video differ in size"
        );
        let pixels: Vec<u8> = frame.rgb.chunks_exact(3).map(index).collect();
        let mut f = gif::Frame::from_indexed_pixels(w, h, pixels, None);
        f.delay = delay;
        encoder.write_frame(&f)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_read_back_in_their_number_size_and_nearest_colours() {
        let mut frames = Vec::new();
        for k in 0..5u8 {
            let mut rgb = vec![0u8; 8 * 6 * 3];
            // One pixel red per frame, at x = k.
            rgb[3 * k as usize] = 255;
            frames.push(Frame {
                width: 8,
                height: 6,
                rgb,
            });
        }
        let mut bytes = Vec::new();
        write(&frames, 30, &mut bytes).unwrap();
        let mut options = gif::DecodeOptions::new();
        options.set_color_output(gif::ColorOutput::RGBA);
        let mut decoder = options.read_info(bytes.as_slice()).unwrap();
        let mut k = 0;
        while let Some(frame) = decoder.read_next_frame().unwrap() {
            assert_eq!((frame.width, frame.height, frame.delay), (8, 6, 3));
            assert_eq!(&frame.buffer[4 * k..4 * k + 3], &[255, 0, 0]);
            assert_eq!(&frame.buffer[4 * (k + 1) % 32..][..3], &[0, 0, 0]);
            k += 1;
        }
        assert_eq!(k, 5);
    }

    #[test]
    fn every_palette_colour_maps_to_itself() {
        let p = palette();
        assert_eq!(p.len(), 3 * 252);
        for (i, rgb) in p.chunks(3).enumerate() {
            assert_eq!(index(rgb) as usize, i);
        }
    }
}
