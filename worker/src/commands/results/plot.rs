//! The study's plots as PNG (plotters): per algorithm, the mean of its seeds' training curves
//! as a line and ±1 std as a band, at the environment steps every seed still running reported
//! (runs of one algorithm share the rollout size, so their iterations line up; a run that
//! stopped early leaves the band there), and the performance profile of the evaluations.

use std::collections::BTreeMap;
use std::path::Path;

use plotters::prelude::*;

use super::record::{CurvePoint, Study};

const FONT: &[u8] = include_bytes!("../../../assets/DejaVuSans.ttf");

/// One algorithm's curve: (steps, mean, std) over its seeds.
type Band = (String, Vec<(f64, f64, f64)>);

fn bands_of(study: &Study, value: &impl Fn(&CurvePoint) -> f64) -> Vec<Band> {
    study
        .file
        .algorithms
        .iter()
        .filter(|a| study.runs_of(a).next().is_some())
        .map(|algorithm| {
            let mut at: BTreeMap<u64, Vec<f64>> = BTreeMap::new();
            // Points past the shortest run's end are kept while at least half the seeds run.
            let runs: Vec<_> = study.runs_of(algorithm).collect();
            for run in &runs {
                for it in run.curve.iter().filter(|it| it.episodes > 0) {
                    let v = value(it);
                    if v.is_finite() {
                        at.entry(it.steps).or_default().push(v);
                    }
                }
            }
            let points = at
                .into_iter()
                .filter(|(_, values)| 2 * values.len() >= runs.len())
                .map(|(steps, values)| {
                    let n = values.len() as f64;
                    let mean = values.iter().sum::<f64>() / n;
                    let std = (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n).sqrt();
                    (steps as f64, mean, std)
                })
                .collect();
            (algorithm.clone(), points)
        })
        .collect()
}

/// A curve's point with its band: (steps, mean, band low, band high).
type Clipped = (f64, f64, f64, f64);

/// Each point's mean ± std, clipped to `range`.
fn clipped(points: &[(f64, f64, f64)], range: Option<(f64, f64)>) -> Vec<Clipped> {
    let clip = |y: f64| range.map_or(y, |(lo, hi)| y.clamp(lo, hi));
    points
        .iter()
        .map(|&(x, mean, std)| (x, mean, clip(mean - std), clip(mean + std)))
        .collect()
}

/// Draws every algorithm's band and mean line to `path`; `range` bounds what the value can
/// be (a success rate's [0, 1]), and the bands are clipped to it.
pub fn bands(
    study: &Study,
    path: &Path,
    title: &str,
    range: Option<(f64, f64)>,
    value: impl Fn(&CurvePoint) -> f64,
) -> anyhow::Result<()> {
    let curves: Vec<(String, Vec<Clipped>)> = bands_of(study, &value)
        .into_iter()
        .map(|(algorithm, points)| (algorithm, clipped(&points, range)))
        .collect();
    draw(path, title, "environment steps", &curves)
}

/// The performance profile: per algorithm, the share of run x task success rates above each
/// threshold in [0, 1], with no band (`profiles`: algorithm, (threshold, share) points).
pub fn profile(path: &Path, profiles: &[(String, Vec<(f64, f64)>)]) -> anyhow::Result<()> {
    let curves: Vec<(String, Vec<Clipped>)> = profiles
        .iter()
        .map(|(a, points)| {
            (
                a.clone(),
                points.iter().map(|&(x, y)| (x, y, y, y)).collect(),
            )
        })
        .collect();
    draw(
        path,
        "performance profile: share of run x task scores > threshold",
        "success rate threshold",
        &curves,
    )
}

/// Draws lines with bands to a PNG.
fn draw(
    path: &Path,
    title: &str,
    x_desc: &str,
    curves: &[(String, Vec<Clipped>)],
) -> anyhow::Result<()> {
    // Registering twice is harmless; plotters keeps the first.
    plotters::style::register_font("sans-serif", FontStyle::Normal, FONT)
        .map_err(|_| anyhow::anyhow!("the bundled font is not a font"))?;
    let (width, height) = (900, 540);
    let mut pixels = vec![0u8; width as usize * height as usize * 3];
    let mut draw = || -> Result<(), Box<dyn std::error::Error>> {
        let root = BitMapBackend::with_buffer(&mut pixels, (width, height)).into_drawing_area();
        root.fill(&WHITE)?;
        let x_max = curves
            .iter()
            .flat_map(|(_, p)| p.iter().map(|p| p.0))
            .fold(1.0, f64::max);
        let lo = curves
            .iter()
            .flat_map(|(_, p)| p.iter().map(|p| p.2))
            .fold(f64::INFINITY, f64::min)
            .min(0.0);
        let hi = curves
            .iter()
            .flat_map(|(_, p)| p.iter().map(|p| p.3))
            .fold(f64::NEG_INFINITY, f64::max)
            .max(lo + 1e-6);
        let hi = if hi <= 1.0 && lo >= 0.0 { 1.0 } else { hi };
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 22))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(0.0..x_max, lo..hi)?;
        chart
            .configure_mesh()
            .x_desc(x_desc)
            .label_style(("sans-serif", 14))
            .draw()?;
        for (k, (algorithm, points)) in curves.iter().enumerate() {
            let color = Palette99::pick(k).to_rgba();
            let band: Vec<(f64, f64)> = points
                .iter()
                .map(|p| (p.0, p.3))
                .chain(points.iter().rev().map(|p| (p.0, p.2)))
                .collect();
            chart.draw_series(std::iter::once(Polygon::new(band, color.mix(0.2).filled())))?;
            chart
                .draw_series(LineSeries::new(
                    points.iter().map(|p| (p.0, p.1)),
                    color.stroke_width(2),
                ))?
                .label(algorithm.as_str())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
                });
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .label_font(("sans-serif", 14))
            .draw()?;
        root.present()?;
        Ok(())
    };
    draw().map_err(|e| anyhow::anyhow!("drawing {}: {e}", path.display()))?;
    write_png(path, width, height, &pixels)
}

/// `pixels` (RGB, row by row) as a PNG file, by the `png` crate the rerun SDK's `image`
/// already builds (plotters' own encoder would build an older `image` with JPEG and BMP).
fn write_png(path: &Path, width: u32, height: u32, pixels: &[u8]) -> anyhow::Result<()> {
    let file = std::fs::File::create(path)
        .map_err(|e| anyhow::anyhow!("writing {}: {e}", path.display()))?;
    let mut encoder = png::Encoder::new(std::io::BufWriter::new(file), width, height);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    encoder
        .write_header()
        .and_then(|mut writer| writer.write_image_data(pixels))
        .map_err(|e| anyhow::anyhow!("writing {}: {e}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bands_are_clipped_to_what_the_value_can_be() {
        let points = [(0.0, 0.1, 0.3), (1.0, 0.9, 0.2)];
        assert_eq!(
            clipped(&points, Some((0.0, 1.0))),
            [(0.0, 0.1, 0.0, 0.4), (1.0, 0.9, 0.7, 1.0)]
        );
        assert_eq!(clipped(&points, None)[0].2, 0.1 - 0.3);
    }
}
