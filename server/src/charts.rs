//! Server-rendered SVG charts for the dashboard, drawn with plotters' SVG backend: training
//! curves of one or several runs, TensorBoard-style smoothing, and the mean with a ±1 standard
//! deviation band where several seeds share a configuration (the paper's training-curve
//! figure). Pure functions: the handlers in `api/dashboard.rs` gather the series.

use plotters::prelude::*;

/// The bundled font (DejaVu Sans, also used by `crm results`), so labels measure the same on
/// every machine and no system font is needed.
const FONT: &[u8] = include_bytes!("../../worker/assets/DejaVuSans.ttf");

/// Line colours, the Tableau 10 palette.
const PALETTE: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];

/// One curve: points in x order and, for a group of seeds, the band's half-width per point.
#[derive(Clone, Debug, PartialEq)]
pub struct Series {
    pub label: String,
    pub points: Vec<(f64, f64)>,
    pub band: Option<Vec<f64>>,
}

/// What the chart shows besides its series.
#[derive(Clone, Debug)]
pub struct Chart<'a> {
    pub title: &'a str,
    pub x_label: &'a str,
    pub y_label: &'a str,
    /// A fixed y range (success rates, shares), else fitted to the data.
    pub y_range: Option<(f64, f64)>,
    pub size: (u32, u32),
}

/// TensorBoard's smoothing: an exponential moving average with the start-up bias removed, so
/// the first points are not pulled towards zero. `weight` in [0, 1); 0 leaves the series.
/// Missing values (NaN: no episode ended in that iteration) stay missing and are skipped.
pub fn smooth(values: &[f64], weight: f64) -> Vec<f64> {
    if weight <= 0.0 {
        return values.to_vec();
    }
    let mut last = 0.0;
    let mut scale = 1.0;
    values
        .iter()
        .map(|&v| {
            if v.is_nan() {
                return v;
            }
            last = last * weight + (1.0 - weight) * v;
            scale *= weight;
            last / (1.0 - scale)
        })
        .collect()
}

/// The mean and standard deviation across several runs' values, point by point, over the
/// length of the shortest run (runs of one configuration report at the same steps).
pub fn mean_and_std(runs: &[Vec<f64>]) -> (Vec<f64>, Vec<f64>) {
    let len = runs.iter().map(Vec::len).min().unwrap_or(0);
    let n = runs.len() as f64;
    (0..len)
        .map(|k| {
            let mean = runs.iter().map(|r| r[k]).sum::<f64>() / n;
            let var = runs.iter().map(|r| (r[k] - mean).powi(2)).sum::<f64>() / n;
            (mean, var.sqrt())
        })
        .unzip()
}

/// Draws `series` as an SVG document. A chart without points says so in its middle.
pub fn render(chart: &Chart, series: &[Series]) -> Result<String, String> {
    // Registering twice is harmless; plotters keeps the first.
    plotters::style::register_font("sans-serif", FontStyle::Normal, FONT)
        .map_err(|_| "the bundled font is not a font".to_string())?;
    let mut svg = String::new();
    draw(&mut svg, chart, series).map_err(|e| format!("drawing {}: {e}", chart.title))?;
    Ok(svg)
}

fn bounds(chart: &Chart, series: &[Series]) -> Option<((f64, f64), (f64, f64))> {
    if series.iter().all(|s| s.points.is_empty()) {
        return None;
    }
    let (mut x0, mut x1) = (f64::INFINITY, f64::NEG_INFINITY);
    let (mut y0, mut y1) = (f64::INFINITY, f64::NEG_INFINITY);
    for s in series {
        for (k, &(x, y)) in s.points.iter().enumerate() {
            let half = s
                .band
                .as_ref()
                .and_then(|b| b.get(k))
                .copied()
                .unwrap_or(0.0);
            x0 = x0.min(x);
            x1 = x1.max(x);
            y0 = y0.min(y - half);
            y1 = y1.max(y + half);
        }
    }
    if let Some(range) = chart.y_range {
        (y0, y1) = range;
    }
    if x1 <= x0 {
        x1 = x0 + 1.0;
    }
    if y1 <= y0 {
        (y0, y1) = (y0 - 0.5, y1 + 0.5);
    } else if chart.y_range.is_none() {
        let pad = 0.05 * (y1 - y0);
        (y0, y1) = (y0 - pad, y1 + pad);
    }
    Some(((x0, x1), (y0, y1)))
}

type DrawResult = Result<(), Box<dyn std::error::Error>>;

fn draw(svg: &mut String, chart: &Chart, series: &[Series]) -> DrawResult {
    let root = SVGBackend::with_string(svg, chart.size).into_drawing_area();
    root.fill(&WHITE)?;
    let Some(((x0, x1), (y0, y1))) = bounds(chart, series) else {
        let style = ("sans-serif", 15)
            .into_font()
            .color(&RGBColor(110, 110, 110));
        root.draw(&Text::new(
            format!("{}: no data yet", chart.title),
            (20, chart.size.1 as i32 / 2),
            style,
        ))?;
        root.present()?;
        return Ok(());
    };
    let mut plot = ChartBuilder::on(&root)
        .caption(chart.title, ("sans-serif", 15))
        .margin(8)
        .x_label_area_size(34)
        .y_label_area_size(52)
        .build_cartesian_2d(x0..x1, y0..y1)?;
    let (x_digits, y_digits) = (digits(x1 - x0), digits(y1 - y0));
    plot.configure_mesh()
        .x_desc(chart.x_label)
        .y_desc(chart.y_label)
        .x_labels(6)
        .y_labels(6)
        .x_label_formatter(&|v| label(*v, x_digits))
        .y_label_formatter(&|v| label(*v, y_digits))
        .light_line_style(RGBColor(238, 238, 238))
        .label_style(("sans-serif", 12))
        .draw()?;
    for (k, s) in series.iter().enumerate() {
        let color = PALETTE[k % PALETTE.len()];
        if let Some(band) = &s.band {
            let outline = band_outline(&s.points, band, chart.y_range);
            plot.draw_series(std::iter::once(Polygon::new(
                outline,
                color.mix(0.18).filled(),
            )))?;
        }
        plot.draw_series(LineSeries::new(
            s.points.iter().copied(),
            color.stroke_width(2),
        ))?
        .label(s.label.as_str())
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(3)));
    }
    if !series.is_empty() {
        plot.configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(RGBColor(200, 200, 200))
            .label_font(("sans-serif", 12))
            .position(SeriesLabelPosition::LowerRight)
            .draw()?;
    }
    root.present()?;
    Ok(())
}

/// A band's outline: the upper edge left to right, then the lower edge back, clipped to a
/// fixed y range (a success rate's ±1 std stops at 0 and 1).
fn band_outline(
    points: &[(f64, f64)],
    band: &[f64],
    y_range: Option<(f64, f64)>,
) -> Vec<(f64, f64)> {
    let clip = |y: f64| y_range.map_or(y, |(lo, hi)| y.clamp(lo, hi));
    let upper = points.iter().zip(band).map(|(&(x, y), h)| (x, clip(y + h)));
    let lower = points
        .iter()
        .zip(band)
        .rev()
        .map(|(&(x, y), h)| (x, clip(y - h)));
    upper.chain(lower).collect()
}

/// Decimals that tell ticks about a sixth of `span` apart: `None` for k/M labels, `Some(9)`
/// for scientific notation.
fn digits(span: f64) -> Option<usize> {
    if span >= 1e4 {
        return None;
    }
    let step = (span / 6.0).max(f64::MIN_POSITIVE);
    // Ticks fall on 1, 2 or 5 times a power of ten: one decimal more than the step's.
    let decimals = if step >= 1.0 {
        0
    } else {
        (-step.log10()).ceil() as usize + 1
    };
    Some(if decimals > 4 { 9 } else { decimals })
}

/// An axis label: 12k, 1.5M, 0.25, 3.0e-4.
fn label(v: f64, digits: Option<usize>) -> String {
    match digits {
        None if v.abs() >= 1e6 => format!("{:.1}M", v / 1e6),
        None if v.abs() >= 1e3 => format!("{:.0}k", v / 1e3),
        None => format!("{v:.0}"),
        Some(9) => format!("{v:.1e}"),
        Some(d) => format!("{v:.d$}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chart() -> Chart<'static> {
        Chart {
            title: "success rate",
            x_label: "steps",
            y_label: "success",
            y_range: Some((0.0, 1.0)),
            size: (480, 300),
        }
    }

    #[test]
    fn smoothing_is_tensorboards_debiased_average() {
        assert_eq!(smooth(&[1.0, 3.0], 0.0), vec![1.0, 3.0]);
        let s = smooth(&[1.0, 3.0], 0.5);
        // First point unbiased; second: (0.25 + 1.5) / 0.75.
        assert!((s[0] - 1.0).abs() < 1e-12);
        assert!((s[1] - 1.75 / 0.75).abs() < 1e-12);
        // A constant series stays constant.
        assert!(
            smooth(&[2.0; 5], 0.9)
                .iter()
                .all(|v| (v - 2.0).abs() < 1e-12)
        );
    }

    #[test]
    fn labels_show_as_many_decimals_as_the_range_needs() {
        assert_eq!(label(12_000.0, digits(50_000.0)), "12k");
        assert_eq!(label(2_500_000.0, digits(5e6)), "2.5M");
        assert_eq!(label(0.25, digits(1.0)), "0.25");
        assert_eq!(label(2.815, digits(0.06)), "2.815");
        assert_eq!(label(0.0003, digits(0.0001)), "3.0e-4");
        assert_eq!(label(350.0, digits(500.0)), "350");
        // Missing values stay missing through smoothing.
        let s = smooth(&[1.0, f64::NAN, 3.0], 0.5);
        assert!(s[1].is_nan() && (s[2] - 1.75 / 0.75).abs() < 1e-12, "{s:?}");
    }

    #[test]
    fn mean_and_std_over_the_shortest_run() {
        let (mean, std) = mean_and_std(&[vec![0.0, 2.0, 9.0], vec![2.0, 2.0]]);
        assert_eq!(mean, vec![1.0, 2.0]);
        assert_eq!(std, vec![1.0, 0.0]);
    }

    #[test]
    fn draws_a_line_per_series_and_a_band_per_group() {
        let series = vec![
            Series {
                label: "run 1".into(),
                points: vec![(0.0, 0.1), (100.0, 0.5), (200.0, 0.9)],
                band: None,
            },
            Series {
                label: "crm-ppo x2 seeds".into(),
                points: vec![(0.0, 0.2), (100.0, 0.4), (200.0, 0.8)],
                band: Some(vec![0.05, 0.1, 0.05]),
            },
        ];
        let svg = render(&chart(), &series).expect("svg");
        assert!(svg.starts_with("<svg"), "{}", &svg[..80]);
        // Two data lines plus two legend marks; one band.
        assert!(svg.matches("<polyline").count() >= 2, "{svg}");
        assert_eq!(svg.matches("<polygon").count(), 1, "{svg}");
        assert!(svg.contains("crm-ppo x2 seeds"));
    }

    #[test]
    fn a_band_stays_inside_a_fixed_range() {
        let points = [(0.0, 0.1), (1.0, 0.95)];
        let band = [0.2, 0.1];
        assert_eq!(
            band_outline(&points, &band, Some((0.0, 1.0))),
            [
                (0.0, 0.30000000000000004),
                (1.0, 1.0),
                (1.0, 0.85),
                (0.0, 0.0)
            ]
        );
        let free = band_outline(&points, &band, None);
        assert!(free[1].1 > 1.0 && free[3].1 < 0.0);
    }

    #[test]
    fn an_empty_chart_says_no_data() {
        let svg = render(&chart(), &[]).expect("svg");
        assert!(svg.contains("no data yet"));
        assert_eq!(svg.matches("<polyline").count(), 0);
    }
}
