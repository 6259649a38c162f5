//! SVG line plots and grouped bar charts for reports (plotters' SVG backend: no system fonts needed, text is left to
//! the viewer).

use plotters::prelude::*;

/// One named curve.
#[derive(Clone, Debug)]
pub struct Series {
    /// Legend label.
    pub label: String,
    /// Points `(x, y)`; non-finite points are skipped.
    pub points: Vec<(f64, f64)>,
}

/// Colors of successive series.
const PALETTE: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(90, 90, 90),
];

/// A line plot of `series` as an SVG document. The y range starts at 0 and ends at the largest
/// finite y (capped at `y_cap` when given, so that a diverging curve does not flatten the
/// others).
pub fn line_plot_svg(
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
    y_cap: Option<f64>,
) -> anyhow::Result<String> {
    let finite = series
        .iter()
        .flat_map(|s| &s.points)
        .filter(|(x, y)| x.is_finite() && y.is_finite());
    let (mut x0, mut x1, mut y1) = (f64::INFINITY, f64::NEG_INFINITY, 0.0f64);
    for &(x, y) in finite {
        x0 = x0.min(x);
        x1 = x1.max(x);
        y1 = y1.max(y);
    }
    if x0.partial_cmp(&x1) != Some(std::cmp::Ordering::Less) {
        (x0, x1) = (0.0, 1.0);
    }
    if let Some(c) = y_cap {
        y1 = y1.min(c);
    }
    if y1 <= 0.0 {
        y1 = 1.0;
    }
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (720, 400)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_err)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 18))
            .margin(12)
            .x_label_area_size(36)
            .y_label_area_size(50)
            .build_cartesian_2d(x0..x1, 0.0..y1 * 1.05)
            .map_err(plot_err)?;
        chart
            .configure_mesh()
            .x_desc(x_label)
            .y_desc(y_label)
            .draw()
            .map_err(plot_err)?;
        for (i, s) in series.iter().enumerate() {
            let color = PALETTE[i % PALETTE.len()];
            let pts: Vec<(f64, f64)> = s
                .points
                .iter()
                .copied()
                .filter(|(x, y)| x.is_finite() && y.is_finite())
                .map(|(x, y)| (x, y.min(y1 * 1.05)))
                .collect();
            chart
                .draw_series(LineSeries::new(pts, color.stroke_width(2)))
                .map_err(plot_err)?
                .label(s.label.clone())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color));
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(plot_err)?;
        root.present().map_err(plot_err)?;
    }
    Ok(svg)
}

/// A grouped bar chart as an SVG document: one group of bars per category (x axis), one bar per
/// named series in each group (the papers' per-term ablation bars). Non-finite values draw no
/// bar; the y range starts at 0.
pub fn bar_plot_svg(
    title: &str,
    y_label: &str,
    categories: &[String],
    series: &[(String, Vec<f64>)],
) -> anyhow::Result<String> {
    let y1 = series
        .iter()
        .flat_map(|(_, v)| v)
        .copied()
        .filter(|y| y.is_finite())
        .fold(0.0f64, f64::max);
    let y1 = if y1 > 0.0 { y1 * 1.1 } else { 1.0 };
    let n = categories.len().max(1);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (720, 400)).into_drawing_area();
        root.fill(&WHITE).map_err(plot_err)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 18))
            .margin(12)
            .x_label_area_size(36)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..n as f64, 0.0..y1)
            .map_err(plot_err)?;
        let names = categories.to_vec();
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_labels(n * 2 + 1)
            .x_label_formatter(&|x| {
                let i = x.floor();
                if (x - i - 0.5).abs() < 1e-6 && i >= 0.0 {
                    names.get(i as usize).cloned().unwrap_or_default()
                } else {
                    String::new()
                }
            })
            .y_desc(y_label)
            .draw()
            .map_err(plot_err)?;
        let width = 0.8 / series.len().max(1) as f64;
        for (j, (label, values)) in series.iter().enumerate() {
            let color = PALETTE[j % PALETTE.len()];
            let bars = values
                .iter()
                .enumerate()
                .filter(|(_, y)| y.is_finite())
                .map(move |(i, &y)| {
                    let x0 = i as f64 + 0.1 + j as f64 * width;
                    Rectangle::new([(x0, 0.0), (x0 + width, y.min(y1))], color.filled())
                });
            chart
                .draw_series(bars)
                .map_err(plot_err)?
                .label(label.clone())
                .legend(move |(x, y)| {
                    Rectangle::new([(x, y - 5), (x + 15, y + 5)], color.filled())
                });
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(plot_err)?;
        root.present().map_err(plot_err)?;
    }
    Ok(svg)
}

/// The papers' "% of frames with error < ε" plot (thesis Fig. 3.14, 4.8): for each named list of
/// per-frame errors (mm), the fraction of its frames under ε for ε in `[0, max_epsilon]` (`steps`
/// + 1 samples), in percent.
pub fn under_curve_svg(
    title: &str,
    errors: &[(String, Vec<f64>)],
    max_epsilon: f64,
    steps: usize,
) -> anyhow::Result<String> {
    anyhow::ensure!(
        max_epsilon.is_finite() && max_epsilon > 0.0 && steps > 0,
        "ε range must be positive with at least one step"
    );
    let eps: Vec<f64> = (0..=steps)
        .map(|i| max_epsilon * i as f64 / steps as f64)
        .collect();
    let series: Vec<Series> = errors
        .iter()
        .map(|(label, values)| Series {
            label: label.clone(),
            points: eps
                .iter()
                .zip(crate::markers::under_curve(values, &eps))
                .map(|(&e, f)| (e, 100.0 * f))
                .collect(),
        })
        .collect();
    line_plot_svg(
        title,
        "ε (mm)",
        "% frames with error < ε",
        &series,
        Some(100.0),
    )
}

fn plot_err<E: std::fmt::Display>(e: E) -> anyhow::Error {
    anyhow::anyhow!("plot: {e}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plots_two_series_and_skips_non_finite_points() {
        let s = [
            Series {
                label: "front-facing".into(),
                points: vec![(0.0, 1.0), (1.0, 2.0), (2.0, f64::NAN)],
            },
            Series {
                label: "closest point".into(),
                points: vec![(0.0, 3.0), (2.0, 1e9)],
            },
        ];
        let svg = line_plot_svg("errors", "frame", "mm", &s, Some(50.0)).unwrap();
        assert!(svg.starts_with("<svg") && svg.contains("front-facing"));
        assert!(svg.contains("closest point") && !svg.contains("NaN"));
        let empty = line_plot_svg("empty", "x", "y", &[], None).unwrap();
        let curves = under_curve_svg("nyu", &[("a".into(), vec![1.0, 30.0])], 50.0, 50).unwrap();
        assert!(
            curves.contains("frames with error") && curves.contains("nyu"),
            "{curves}"
        );
        assert!(under_curve_svg("bad", &[], f64::NAN, 10).is_err());
        assert!(empty.contains("</svg>"));
    }

    #[test]
    fn bar_plot_groups_series_by_category() {
        let terms = vec!["d2m".to_string(), "m2d".to_string()];
        let s = vec![
            ("cylinders".to_string(), vec![3.0, f64::NAN]),
            ("spheremesh".to_string(), vec![2.0, 1.0]),
        ];
        let svg = bar_plot_svg("energies", "energy", &terms, &s).unwrap();
        assert!(svg.contains("spheremesh") && svg.contains("d2m") && !svg.contains("NaN"));
        assert!(bar_plot_svg("none", "y", &[], &[])
            .unwrap()
            .contains("</svg>"));
    }
}
