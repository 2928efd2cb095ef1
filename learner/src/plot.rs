//! Charts for people: PNG pictures with a title, labelled axes and a legend
//! (the jitter harness's latency histograms; next, learning curves and
//! evaluation results). Drawn with plotters into a pixel buffer in DejaVu
//! Sans, which ships in `learner/assets/` so that no system font is needed,
//! and written with [`stack_common::png`].

use plotters::coord::Shift;
use plotters::coord::ranged1d::{AsRangedCoord, Ranged, ValueFormatter};
use plotters::prelude::*;
use plotters::style::text_anchor;
use std::ops::Range;
use std::path::Path;
use std::sync::OnceLock;

/// The font every chart is drawn in (licence: `assets/DejaVuSans-LICENSE.txt`).
const FONT: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");
/// The family name it is registered under.
const FAMILY: &str = "sans-serif";
/// Series colours, in order (matplotlib's first five: told apart by most
/// colour-blind readers).
const PALETTE: [RGBColor; 5] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
];

/// Why a chart could not be drawn or written.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// The shipped font could not be read (a damaged build).
    #[error("the chart font could not be loaded")]
    Font,
    /// plotters failed.
    #[error("drawing the chart '{title}': {detail}")]
    Draw {
        /// The chart's title.
        title: String,
        /// plotters' error.
        detail: String,
    },
    /// The picture could not be written.
    #[error(transparent)]
    Png(#[from] stack_common::png::PngError),
}

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Style {
    /// A line through the points.
    Line,
    /// Bars of this width starting at each point's x, height its y,
    /// translucent so that overlapping histograms stay readable.
    Histogram {
        /// Bar width, in x units.
        bin_width: f64,
    },
    /// Unconnected dots (a scatter plot).
    Points,
    /// Separate bars of this width starting at each point's x, each
    /// outlined and labelled with its value (categorical bar charts).
    Bars {
        /// Bar width, in x units.
        width: f64,
    },
}

/// One named series of (x, y) points; its name goes in the legend.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// Legend entry.
    pub name: String,
    /// The points, in x order.
    pub points: Vec<(f64, f64)>,
    /// How it is drawn.
    pub style: Style,
}

impl Series {
    /// A line through `points`.
    pub fn line(name: &str, points: Vec<(f64, f64)>) -> Self {
        Self {
            name: name.into(),
            points,
            style: Style::Line,
        }
    }

    /// Unconnected dots at `points`.
    pub fn points(name: &str, points: Vec<(f64, f64)>) -> Self {
        Self {
            name: name.into(),
            points,
            style: Style::Points,
        }
    }

    /// Bars for categories: value `i` over `[i + offset, i + offset +
    /// width)` (with [`Chart::with_categories`], category `i` sits at x = i).
    pub fn bars(name: &str, values: &[f64], offset: f64, width: f64) -> Self {
        Self {
            name: name.into(),
            points: values
                .iter()
                .enumerate()
                .map(|(i, &v)| (i as f64 + offset, v))
                .collect(),
            style: Style::Bars { width },
        }
    }

    /// A histogram: `counts[i]` over `[start + i·width, start + (i+1)·width)`.
    pub fn histogram(name: &str, start: f64, width: f64, counts: &[f64]) -> Self {
        Self {
            name: name.into(),
            points: counts
                .iter()
                .enumerate()
                .map(|(i, &c)| (start + i as f64 * width, c))
                .collect(),
            style: Style::Histogram { bin_width: width },
        }
    }

    /// The x extent it covers (a bar reaches its right edge).
    fn x_extent(&self) -> Option<(f64, f64)> {
        let right = match self.style {
            Style::Line | Style::Points => 0.0,
            Style::Histogram { bin_width } => bin_width,
            Style::Bars { width } => width,
        };
        let (lo, hi) = self
            .points
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &(x, _)| {
                (lo.min(x), hi.max(x + right))
            });
        (lo <= hi).then_some((lo, hi))
    }
}

/// A chart: title, axis labels, y scale, size and series.
#[derive(Debug, Clone, PartialEq)]
pub struct Chart {
    /// Title above the plot.
    pub title: String,
    /// x axis label, with its unit.
    pub x_label: String,
    /// y axis label, with its unit.
    pub y_label: String,
    /// Logarithmic y axis (only positive values are drawn).
    pub log_y: bool,
    /// Picture size, px.
    pub size: (u32, u32),
    /// The series, drawn in order.
    pub series: Vec<Series>,
    /// Names of the x axis's categories (at x = 0, 1, …): the ticks show
    /// them instead of numbers. Empty: a numeric axis.
    pub categories: Vec<String>,
}

impl Chart {
    /// An empty 1000×560 chart with a linear y axis.
    pub fn new(title: &str, x_label: &str, y_label: &str) -> Self {
        Self {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            log_y: false,
            size: (1000, 560),
            series: Vec::new(),
            categories: Vec::new(),
        }
    }

    /// With a categorical x axis: `names[i]` at x = i, the range one half
    /// beyond the first and last.
    pub fn with_categories(mut self, names: Vec<String>) -> Self {
        self.categories = names;
        self
    }

    /// With a logarithmic y axis.
    pub fn log_y(mut self) -> Self {
        self.log_y = true;
        self
    }

    /// With `series` added.
    pub fn with(mut self, series: Series) -> Self {
        self.series.push(series);
        self
    }

    /// The picture: 8-bit RGB, row-major, `size.0 × size.1`.
    pub fn render(&self) -> Result<Vec<u8>, PlotError> {
        register_font()?;
        let (w, h) = self.size;
        let mut px = vec![255u8; w as usize * h as usize * 3];
        let draw_err = |detail: String| PlotError::Draw {
            title: self.title.clone(),
            detail,
        };
        {
            let root = BitMapBackend::with_buffer(&mut px, (w, h)).into_drawing_area();
            root.fill(&WHITE).map_err(|e| draw_err(e.to_string()))?;
            let x = self.x_range();
            let (lo, hi) = self.y_range();
            let drawn = if self.log_y {
                draw(self, &root, x, (lo..hi).log_scale(), lo)
            } else {
                draw(self, &root, x, lo..hi, 0.0f64.clamp(lo, hi))
            };
            drawn.map_err(draw_err)?;
            root.present().map_err(|e| draw_err(e.to_string()))?;
        }
        Ok(px)
    }

    /// Draws the chart into a PNG file at `path`.
    pub fn write_png(&self, path: impl AsRef<Path>) -> Result<(), PlotError> {
        let px = self.render()?;
        stack_common::png::write(path, self.size.0, self.size.1, 3, &px)?;
        Ok(())
    }

    /// The x range covering every series (0..1 when there is none).
    fn x_range(&self) -> Range<f64> {
        if !self.categories.is_empty() {
            return -0.5..self.categories.len() as f64 - 0.5;
        }
        let (lo, hi) = self
            .series
            .iter()
            .filter_map(Series::x_extent)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), (lo, hi)| {
                (a.min(lo), b.max(hi))
            });
        widen(lo, hi)
    }

    /// The y range: from 0 (or the lowest value) to a little above the
    /// highest (a quarter of the range above it for bar charts of
    /// categories, whose legend in the upper right would otherwise cover the
    /// tallest bars' labels); on a log axis from half the smallest positive
    /// value to twice the largest.
    fn y_range(&self) -> (f64, f64) {
        let ys = self
            .series
            .iter()
            .flat_map(|s| s.points.iter().map(|p| p.1))
            .filter(|y| y.is_finite() && (!self.log_y || *y > 0.0));
        let (lo, hi) = ys.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), y| {
            (a.min(y), b.max(y))
        });
        if self.log_y {
            if lo > hi {
                return (0.5, 10.0);
            }
            (lo / 2.0, hi * 2.0)
        } else {
            let r = widen(lo.min(0.0), hi.max(0.0));
            let head = if self.categories.is_empty() {
                0.05
            } else {
                0.25
            };
            (r.start, r.end + head * (r.end - r.start))
        }
    }
}

/// `lo..hi`, or a unit range around them when empty or a single value.
fn widen(lo: f64, hi: f64) -> Range<f64> {
    if lo > hi || !lo.is_finite() || !hi.is_finite() {
        0.0..1.0
    } else if lo == hi {
        lo - 0.5..hi + 0.5
    } else {
        lo..hi
    }
}

/// Registers the shipped font with plotters, once per process.
fn register_font() -> Result<(), PlotError> {
    static DONE: OnceLock<bool> = OnceLock::new();
    let ok = *DONE
        .get_or_init(|| plotters::style::register_font(FAMILY, FontStyle::Normal, FONT).is_ok());
    if ok { Ok(()) } else { Err(PlotError::Font) }
}

/// A tick label: at most four decimals, trailing zeros dropped.
fn tick_label(v: &f64) -> String {
    let s = format!("{v:.4}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" { "0".into() } else { s.into() }
}

/// Draws `chart` on `root` with y axis `y`; bars stand on `y_floor`.
/// Generic over the y axis so that linear and log charts share the code.
fn draw<Y>(
    chart: &Chart,
    root: &DrawingArea<BitMapBackend<'_>, Shift>,
    x: Range<f64>,
    y: Y,
    y_floor: f64,
) -> Result<(), String>
where
    Y: AsRangedCoord<Value = f64>,
    Y::CoordDescType: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    let e = |err: &dyn std::fmt::Display| err.to_string();
    // A category's name at its integer x, nothing between.
    let category = |v: &f64| {
        let i = v.round();
        if (v - i).abs() < 1e-6 && i >= 0.0 {
            chart
                .categories
                .get(i as usize)
                .cloned()
                .unwrap_or_default()
        } else {
            String::new()
        }
    };
    let x_format: &dyn Fn(&f64) -> String = if chart.categories.is_empty() {
        &tick_label
    } else {
        &category
    };
    let mut ctx = ChartBuilder::on(root)
        .caption(&chart.title, (FAMILY, 26))
        .margin(18)
        .x_label_area_size(56)
        .y_label_area_size(80)
        .build_cartesian_2d(x, y)
        .map_err(|x| e(&x))?;
    ctx.configure_mesh()
        .x_desc(&chart.x_label)
        .y_desc(&chart.y_label)
        .axis_desc_style((FAMILY, 20))
        .label_style((FAMILY, 16))
        .x_label_formatter(x_format)
        .x_labels(if chart.categories.is_empty() {
            10
        } else {
            chart.categories.len()
        })
        .y_label_formatter(&tick_label)
        .bold_line_style(RGBColor(215, 215, 215))
        .light_line_style(RGBColor(240, 240, 240))
        .draw()
        .map_err(|x| e(&x))?;
    let log_y = chart.log_y;
    for (i, s) in chart.series.iter().enumerate() {
        let color = PALETTE[i % PALETTE.len()];
        match s.style {
            Style::Line => {
                ctx.draw_series(LineSeries::new(
                    s.points.iter().copied().filter(|p| !log_y || p.1 > 0.0),
                    color.stroke_width(2),
                ))
                .map_err(|x| e(&x))?
                .label(&s.name)
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 24, y)], color.stroke_width(2))
                });
            }
            Style::Points => {
                ctx.draw_series(
                    s.points
                        .iter()
                        .filter(|p| !log_y || p.1 > 0.0)
                        .map(|&p| Circle::new(p, 2, color.mix(0.6).filled())),
                )
                .map_err(|x| e(&x))?
                .label(&s.name)
                .legend(move |(x, y)| Circle::new((x + 12, y), 4, color.filled()));
            }
            Style::Bars { width } => {
                let bars = s
                    .points
                    .iter()
                    .filter(|p| p.1.is_finite() && (!log_y || p.1 > 0.0))
                    .map(|&(x0, c)| {
                        Rectangle::new([(x0, y_floor), (x0 + width, c)], color.mix(0.5).filled())
                    });
                ctx.draw_series(bars)
                    .map_err(|x| e(&x))?
                    .label(&s.name)
                    .legend(move |(x, y)| {
                        Rectangle::new([(x, y - 7), (x + 24, y + 7)], color.mix(0.6).filled())
                    });
            }
            Style::Histogram { bin_width } => {
                // Empty bins draw nothing (and have no place on a log axis).
                let shown = |c: f64| if log_y { c > 0.0 } else { c != 0.0 };
                let bars = s.points.iter().filter(|p| shown(p.1)).map(|&(x0, c)| {
                    Rectangle::new(
                        [(x0, y_floor), (x0 + bin_width, c)],
                        color.mix(0.35).filled(),
                    )
                });
                ctx.draw_series(bars)
                    .map_err(|x| e(&x))?
                    .label(&s.name)
                    .legend(move |(x, y)| {
                        Rectangle::new([(x, y - 7), (x + 24, y + 7)], color.mix(0.6).filled())
                    });
                // The outline, so that overlapping bars stay apart.
                let outline = s.points.iter().flat_map(|&(x0, c)| {
                    let c = if log_y { c.max(y_floor) } else { c };
                    [(x0, c), (x0 + bin_width, c)]
                });
                ctx.draw_series(LineSeries::new(outline, color.stroke_width(1)))
                    .map_err(|x| e(&x))?;
            }
        }
    }
    for (i, s) in chart.series.iter().enumerate() {
        let Style::Bars { width } = s.style else {
            continue;
        };
        let color = PALETTE[i % PALETTE.len()];
        let shown = |c: f64| c.is_finite() && (!log_y || c > 0.0);
        ctx.draw_series(s.points.iter().filter(|p| shown(p.1)).map(|&(x0, c)| {
            Rectangle::new([(x0, y_floor), (x0 + width, c)], color.stroke_width(1))
        }))
        .map_err(|x| e(&x))?;
        // The value above each bar: a bar of 0 is otherwise invisible.
        ctx.draw_series(s.points.iter().filter(|p| shown(p.1)).map(|&(x0, c)| {
            Text::new(
                tick_label(&((c * 10.0).round() / 10.0)),
                (x0 + 0.5 * width, c),
                (FAMILY, 16)
                    .into_font()
                    .color(&BLACK)
                    .pos(text_anchor::Pos::new(
                        text_anchor::HPos::Center,
                        text_anchor::VPos::Bottom,
                    )),
            )
        }))
        .map_err(|x| e(&x))?;
    }
    ctx.configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .margin(12)
        .label_font((FAMILY, 18))
        .background_style(WHITE.mix(0.9))
        .border_style(RGBColor(160, 160, 160))
        .draw()
        .map_err(|x| e(&x))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Decodes an RGB PNG: (width, height, pixels).
    fn decode(path: &Path) -> (u32, u32, Vec<u8>) {
        let dec = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
        let mut r = dec.read_info().unwrap();
        let mut buf = vec![0; r.output_buffer_size().unwrap()];
        let info = r.next_frame(&mut buf).unwrap();
        assert_eq!(info.color_type, png::ColorType::Rgb);
        buf.truncate(info.buffer_size());
        (info.width, info.height, buf)
    }

    /// Pixels of exactly `c`.
    fn count(px: &[u8], c: [u8; 3]) -> usize {
        px.chunks_exact(3).filter(|p| *p == c).count()
    }

    #[test]
    fn a_log_histogram_chart_is_drawn_with_its_text_and_series() {
        let counts: Vec<f64> = (0..60)
            .map(|i| (1e5 * (-(i as f64 - 8.0).powi(2) / 20.0).exp()).floor())
            .collect();
        let chart = Chart::new("test chart", "wake-up latency (µs)", "cycles")
            .log_y()
            .with(Series::histogram("first", 0.0, 1.0, &counts))
            .with(Series::line(
                "second",
                (0..60).map(|i| (i as f64, 1.0 + i as f64)).collect(),
            ));
        let tmp = test_support::scratch_dir("plot");
        let path = tmp.join("chart.png");
        chart.write_png(&path).unwrap();
        let (w, h, px) = decode(&path);
        assert_eq!((w, h), chart.size);
        let total = (w * h) as usize;
        let white = count(&px, [255, 255, 255]);
        assert!(
            white < total * 97 / 100,
            "nearly blank: {white} of {total} white"
        );
        assert!(
            white > total / 2,
            "mostly background expected: {white} of {total}"
        );
        // The line in the second colour, exactly; the text in dark grey-black.
        assert!(count(&px, [255, 127, 14]) > 100, "no line drawn");
        let dark = px
            .chunks_exact(3)
            .filter(|p| p.iter().all(|&v| v < 60))
            .count();
        assert!(dark > 2000, "no text or axes: {dark} dark pixels");
    }

    #[test]
    fn empty_and_single_valued_charts_still_draw() {
        let tmp = test_support::scratch_dir("plot-empty");
        Chart::new("empty", "x", "y")
            .write_png(tmp.join("e.png"))
            .unwrap();
        Chart::new("one", "x", "y")
            .log_y()
            .with(Series::histogram("zeros", 0.0, 1.0, &[0.0, 0.0]))
            .with(Series::line("one point", vec![(2.0, 3.0)]))
            .write_png(tmp.join("o.png"))
            .unwrap();
    }

    #[test]
    fn tick_labels_drop_trailing_zeros() {
        assert_eq!(tick_label(&100.0), "100");
        assert_eq!(tick_label(&0.25), "0.25");
        assert_eq!(tick_label(&-0.0), "0");
        assert_eq!(tick_label(&(0.1 + 0.2)), "0.3");
    }
}
