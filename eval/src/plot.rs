//! SVG line plots for reports (plotters' SVG backend: no system fonts needed, text is left to
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
}
