//! Grouped bar charts: a title, a y axis from 0 with round tick values and grid lines, one group of
//! bars per category with its name under a tick, both axes labelled (with units), and a legend when
//! there are several series.

use super::legend::{legend_size, LegendItem, Swatch};
use super::text::{self, measure, Align, TextStyle};
use super::{Rgb, RgbImage, GRID, INK, WHITE};

/// One series of a grouped bar chart.
#[derive(Debug, Clone)]
pub struct Series {
    /// Legend label.
    pub name: String,
    /// Bar colour.
    pub colour: Rgb,
    /// One value per category.
    pub values: Vec<f64>,
}

/// A grouped bar chart to draw.
#[derive(Debug, Clone)]
pub struct BarChart {
    /// Title, above the plot.
    pub title: String,
    /// What the categories are (under the x axis), with the unit, e.g. `instances per image`.
    pub x_label: String,
    /// What the bars measure (along the y axis), with the unit, e.g. `images`.
    pub y_label: String,
    /// Category names, one per group of bars.
    pub categories: Vec<String>,
    /// The series, one bar per category each.
    pub series: Vec<Series>,
}

/// Where a drawn chart put its plot: the plot area and the value at its top.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChartLayout {
    /// Left edge of the plot area (the y axis is the column just left of it), px.
    pub plot_left: i64,
    /// Top of the plot area (the top tick's row), px.
    pub plot_top: i64,
    /// Width of the plot area, px.
    pub plot_width: i64,
    /// Height of the plot area (the x axis is the row just below it), px.
    pub plot_height: i64,
    /// The value at the top of the y axis (the last tick).
    pub y_max: f64,
}

/// Height of the plot area, px.
const PLOT_H: i64 = 280;
/// Narrowest chart, px.
const MIN_WIDTH: i64 = 560;

/// Round tick values from 0 up to at least `max`: steps of 1, 2 or 5 × 10ⁿ, about `target` of them
/// (at least one step; integer steps when `integers`).
pub fn nice_ticks(max: f64, target: usize, integers: bool) -> Vec<f64> {
    let max = if max.is_finite() && max > 0.0 { max } else { 1.0 };
    let raw = max / target.max(1) as f64;
    let p = 10f64.powf(raw.log10().floor());
    let mut step = [1.0, 2.0, 5.0, 10.0].into_iter().map(|k| k * p).find(|&s| s >= raw).unwrap_or(10.0 * p);
    if integers {
        step = step.max(1.0).round();
    }
    let n = (max / step - 1e-9).ceil().max(1.0) as usize;
    (0..=n).map(|i| i as f64 * step).collect()
}

/// A tick value with as many decimals as its step needs (`0.25` → 2, `5` → 0).
pub fn format_tick(v: f64, step: f64) -> String {
    let exact = |d: usize| {
        let scaled = step * 10f64.powi(d as i32);
        (scaled.round() - scaled).abs() <= 1e-6 * scaled.abs().max(1.0)
    };
    let decimals = (0..6).find(|&d| exact(d)).unwrap_or(6);
    format!("{v:.decimals$}")
}

impl BarChart {
    /// Draws the chart; returns the image and where its plot area is.
    pub fn draw(&self) -> (RgbImage, ChartLayout) {
        let tick = TextStyle::new(text::TICK_PX, INK);
        let n_cat = self.categories.len().max(1) as i64;
        let n_ser = self.series.len().max(1) as i64;
        let integers = self.series.iter().flat_map(|s| &s.values).all(|v| v.fract() == 0.0);
        let max = self.series.iter().flat_map(|s| s.values.iter().copied()).fold(0.0f64, f64::max);
        let ticks = nice_ticks(max, 5, integers);
        let step = ticks.get(1).copied().unwrap_or(1.0);
        let y_max = *ticks.last().expect("nice_ticks gives two values at least");
        let tick_labels: Vec<String> = ticks.iter().map(|&v| format_tick(v, step)).collect();
        // Groups: room for the bars, and for every category name when there are few.
        let bar_w = if n_cat * n_ser > 60 { 5 } else { 14 };
        let widest = self.categories.iter().map(|c| measure(c, text::TICK_PX)[0]).max().unwrap_or(0);
        let label_h = text::line_height(text::LABEL_PX);
        let tick_w = tick_labels.iter().map(|l| measure(l, text::TICK_PX)[0]).max().unwrap_or(0);
        let left = 12 + label_h + 10 + tick_w + 8;
        // Few categories spread over the narrowest chart rather than crowd its left side.
        let group_w = if n_cat <= 12 {
            (n_ser * bar_w + 10).max(widest + 14).max((MIN_WIDTH - 24 - left) / n_cat)
        } else {
            n_ser * bar_w + 6
        };
        let legend: Vec<LegendItem> =
            self.series.iter().map(|s| LegendItem::new(Swatch::Square(s.colour), s.name.clone())).collect();
        let show_legend = self.series.len() > 1;
        let title_h = text::line_height(text::TITLE_PX);
        let plot_w = n_cat * group_w;
        let width = (left + plot_w + 24).max(MIN_WIDTH).max(measure(&self.title, text::TITLE_PX)[0] + 24);
        let [leg_w, leg_h] =
            if show_legend { legend_size(&legend, text::TICK_PX, width - left) } else { [0, 0] };
        let top = 12 + title_h + 10 + if show_legend { leg_h + 10 } else { 0 } + 8;
        let tick_h = text::line_height(text::TICK_PX);
        let height = top + PLOT_H + 8 + tick_h + 8 + label_h + 12;
        let mut img = RgbImage::new(width as u32, height as u32, WHITE);
        img.text(12, 12, &self.title, TextStyle::new(text::TITLE_PX, INK));
        if show_legend {
            img.legend(width - 12 - leg_w, 12 + title_h + 10, &legend, text::TICK_PX, width - left);
        }
        // Grid lines and y ticks with their values.
        for (v, label) in ticks.iter().zip(&tick_labels) {
            let y = top + PLOT_H - (v / y_max * PLOT_H as f64).round() as i64;
            img.fill_rect(left, y, plot_w, 1, GRID);
            img.fill_rect(left - 6, y, 5, 1, INK);
            img.text(left - 9, y - tick_h / 2, label, tick.aligned(Align::Right));
        }
        // Bars, then the category ticks and names (every k-th when they do not all fit).
        let every = (widest + 10) / group_w + 1;
        for (ci, cat) in self.categories.iter().enumerate() {
            let gx = left + ci as i64 * group_w;
            let bars_x = gx + (group_w - n_ser * bar_w) / 2;
            for (si, s) in self.series.iter().enumerate() {
                let v = s.values.get(ci).copied().unwrap_or(0.0);
                let h = (v / y_max * PLOT_H as f64).round() as i64;
                let h = if v > 0.0 { h.max(1) } else { h };
                img.fill_rect(bars_x + si as i64 * bar_w, top + PLOT_H - h, bar_w - 1, h, s.colour);
            }
            if ci as i64 % every == 0 {
                let cx = gx + group_w / 2;
                img.fill_rect(cx, top + PLOT_H + 1, 1, 5, INK);
                img.text(cx, top + PLOT_H + 8, cat, tick.aligned(Align::Centre));
            }
        }
        // Axes over the bars' feet, and their labels.
        img.fill_rect(left - 1, top, 1, PLOT_H + 1, INK);
        img.fill_rect(left - 1, top + PLOT_H, plot_w + 1, 1, INK);
        let label = TextStyle::new(text::LABEL_PX, INK);
        img.text(
            left + plot_w / 2,
            top + PLOT_H + 8 + tick_h + 8,
            &self.x_label,
            label.aligned(Align::Centre),
        );
        img.text_upwards(12, top + PLOT_H / 2, &self.y_label, label);
        let layout =
            ChartLayout { plot_left: left, plot_top: top, plot_width: plot_w, plot_height: PLOT_H, y_max };
        (img, layout)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_are_round_and_cover_the_maximum() {
        assert_eq!(nice_ticks(10.0, 5, true), [0.0, 2.0, 4.0, 6.0, 8.0, 10.0]);
        assert_eq!(nice_ticks(11.0, 5, true), [0.0, 5.0, 10.0, 15.0]);
        assert_eq!(nice_ticks(3.0, 5, true), [0.0, 1.0, 2.0, 3.0]);
        assert_eq!(nice_ticks(0.0, 5, true), [0.0, 1.0]);
        assert_eq!(nice_ticks(0.9, 5, false), [0.0, 0.2, 0.4, 0.6000000000000001, 0.8, 1.0]);
        assert_eq!(nice_ticks(1234.0, 5, true).last(), Some(&1500.0));
        assert_eq!(format_tick(0.6000000000000001, 0.2), "0.6");
        assert_eq!(format_tick(0.25, 0.25), "0.25");
        assert_eq!(format_tick(1500.0, 500.0), "1500");
    }

    fn chart(values: Vec<Vec<f64>>) -> BarChart {
        let colours = [[200, 30, 30], [30, 30, 200]];
        BarChart {
            title: "t".into(),
            x_label: "x (px)".into(),
            y_label: "images".into(),
            categories: vec!["a".into(), "b".into()],
            series: values
                .into_iter()
                .enumerate()
                .map(|(i, v)| Series { name: format!("s{i}"), colour: colours[i], values: v })
                .collect(),
        }
    }

    #[test]
    fn bars_are_proportional_to_the_axis() {
        let (img, l) = chart(vec![vec![10.0, 5.0]]).draw();
        assert_eq!(l.y_max, 10.0);
        let red = |x: i64| (0..img.height).filter(|&y| img.get(x as u32, y) == [200, 30, 30]).count() as i64;
        let reds: Vec<i64> = (l.plot_left..l.plot_left + l.plot_width).map(red).filter(|&n| n > 0).collect();
        // Two bars 13 px wide: the full height, and half of it.
        assert_eq!(reds.len(), 26);
        assert_eq!((reds[0], reds[25]), (l.plot_height, l.plot_height / 2));
        // One series: no legend, so red appears only in the bars.
        assert_eq!(img.data.chunks_exact(3).filter(|p| *p == [200, 30, 30]).count() as i64, 13 * 420);
    }

    #[test]
    fn several_series_get_a_legend_and_text_is_drawn_everywhere_it_belongs() {
        let (img, l) = chart(vec![vec![3.0, 7.0], vec![1.0, 0.0]]).draw();
        let inked = |x0: i64, y0: i64, x1: i64, y1: i64| {
            (y0..y1).any(|y| {
                (x0..x1).any(|x| img.get(x as u32, y as u32)[0] < 128 && img.get(x as u32, y as u32)[1] < 128)
            })
        };
        // y tick values left of the axis, the y label further left, category names and the x label
        // under the axis, the title above.
        assert!(inked(l.plot_left - 40, l.plot_top - 8, l.plot_left - 8, l.plot_top + 8), "top tick value");
        assert!(inked(0, l.plot_top, 30, l.plot_top + l.plot_height), "y label");
        assert!(
            inked(l.plot_left, l.plot_top + l.plot_height + 6, l.plot_left + l.plot_width, img.height as i64),
            "x names"
        );
        assert!(inked(0, 0, img.width as i64, 30), "title");
        // The legend's blue square beyond the single blue bar: more blue than the bar alone.
        let blue = img.data.chunks_exact(3).filter(|p| *p == [30, 30, 200]).count() as i64;
        let bar = 13 * (l.plot_height / 8);
        assert_eq!(blue, bar + 12 * 12);
    }
}
