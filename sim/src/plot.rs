//! SVG figures of the summary: grouped bars (one group per initial speed, one bar per
//! controller) with 95 % confidence whiskers.

use std::path::Path;

use plotters::prelude::*;

use crate::experiment::{ControllerKind, SummaryRow};
use crate::world::ScenarioKind;

const COLOURS: [RGBColor; 6] = [
    RGBColor(120, 120, 120),
    RGBColor(70, 130, 180),
    RGBColor(230, 145, 56),
    RGBColor(60, 160, 90),
    RGBColor(150, 90, 170),
    RGBColor(200, 80, 90),
];

/// Draws one panel per `(metric, label)` for `scenario` into `file` (SVG).
pub fn bars(
    file: &Path,
    title: &str,
    rows: &[SummaryRow],
    scenario: ScenarioKind,
    metrics: &[(&str, &str)],
) -> Result<(), String> {
    let root = SVGBackend::new(file, (420 * metrics.len() as u32, 360)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let root = root
        .titled(title, ("sans-serif", 18))
        .map_err(|e| e.to_string())?;
    let panels = root.split_evenly((1, metrics.len()));
    let rows: Vec<&SummaryRow> = rows.iter().filter(|r| r.scenario == scenario).collect();
    let mut speeds: Vec<f64> = rows.iter().map(|r| r.speed).collect();
    speeds.sort_by(f64::total_cmp);
    speeds.dedup();
    let kinds: Vec<ControllerKind> = ControllerKind::EVERY
        .into_iter()
        .filter(|c| rows.iter().any(|r| r.controller == *c))
        .collect();
    let width = 1.0 / (kinds.len() as f64 + 1.0);
    for (panel, (metric, label)) in panels.iter().zip(metrics) {
        let top = rows
            .iter()
            .map(|r| {
                let (m, ci) = r.get(metric);
                m + if ci.is_finite() { ci } else { 0.0 }
            })
            .filter(|v| v.is_finite())
            .fold(0.0f64, f64::max)
            * 1.15
            + 1e-6;
        let mut chart = ChartBuilder::on(panel)
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(45)
            .build_cartesian_2d(0.0..speeds.len() as f64, 0.0..top)
            .map_err(|e| e.to_string())?;
        let labels = speeds.clone();
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_labels(speeds.len() * 2 + 1)
            .x_label_formatter(&|x| {
                let i = x.floor() as usize;
                if (x - i as f64 - 0.5).abs() < 0.01 && i < labels.len() {
                    format!("{} m/s", labels[i])
                } else {
                    String::new()
                }
            })
            .y_desc(*label)
            .draw()
            .map_err(|e| e.to_string())?;
        for (k, c) in kinds.iter().enumerate() {
            let colour = COLOURS[*c as usize % COLOURS.len()];
            let mut bars = Vec::new();
            let mut whiskers = Vec::new();
            for (i, speed) in speeds.iter().enumerate() {
                let Some(r) = rows
                    .iter()
                    .find(|r| r.controller == *c && r.speed == *speed)
                else {
                    continue;
                };
                let (m, ci) = r.get(metric);
                if !m.is_finite() {
                    continue;
                }
                let x0 = i as f64 + width * (k as f64 + 0.5);
                bars.push(Rectangle::new(
                    [(x0, 0.0), (x0 + width, m)],
                    colour.filled(),
                ));
                if ci.is_finite() {
                    let xm = x0 + width / 2.0;
                    whiskers.push(PathElement::new(
                        vec![(xm, (m - ci).max(0.0)), (xm, m + ci)],
                        BLACK.stroke_width(1),
                    ));
                }
            }
            chart
                .draw_series(bars)
                .map_err(|e| e.to_string())?
                .label(c.name())
                .legend(move |(x, y)| {
                    Rectangle::new([(x, y - 5), (x + 10, y + 5)], colour.filled())
                });
            chart.draw_series(whiskers).map_err(|e| e.to_string())?;
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .label_font(("sans-serif", 11))
            .draw()
            .map_err(|e| e.to_string())?;
    }
    root.present().map_err(|e| e.to_string())
}
