//! Line plots to PNG for docs and reports (hifi figures, surrogate training reports).
//!
//! A thin layer over `plotters` with its bitmap backend and a bundled DejaVu Sans font
//! rendered by `ab_glyph`: no fontconfig, freetype or any other system library is
//! needed to build or to draw. One figure is a stack of panels sharing the width.
//!
//! ```no_run
//! use oils_lab::plot::{write_png, Panel, Series};
//! let pts: Vec<(f64, f64)> = (0..100).map(|i| (i as f64, (i as f64 * 0.1).sin())).collect();
//! let panel = Panel::new("sine", "t [s]", "y [-]", vec![Series { label: "sin", points: &pts }]);
//! write_png(std::path::Path::new("sine.png"), "Example", &[panel])?;
//! # Ok::<(), oils_lab::plot::PlotError>(())
//! ```

use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::prelude::*;
use std::path::Path;
use std::sync::OnceLock;
use thiserror::Error;

/// DejaVu Sans (Bitstream Vera licence, see `assets/DejaVuSans-LICENSE.txt`).
static FONT_TTF: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");
/// Family name under which the bundled font is registered with plotters.
pub(crate) const FONT_FAMILY: &str = "sans-serif";

/// Width of a figure, pixels.
const WIDTH_PX: u32 = 1200;
/// Height of one panel, pixels.
const PANEL_HEIGHT_PX: u32 = 360;
/// Height of the figure title band, pixels.
const TITLE_HEIGHT_PX: u32 = 44;

/// A plot could not be drawn or written.
#[derive(Debug, Error)]
pub enum PlotError {
    /// The bundled font was rejected by the font rasteriser.
    #[error("bundled font could not be loaded")]
    Font,
    /// A figure needs at least one panel.
    #[error("a figure needs at least one panel")]
    NoPanels,
    /// A panel has no finite point to draw (or none > 0 on a log axis).
    #[error("panel `{0}` has no finite point to draw")]
    NoData(String),
    /// The drawing backend failed (includes file I/O while encoding the PNG).
    #[error("drawing {path}: {message}")]
    Backend {
        /// Output file.
        path: String,
        /// Backend's message.
        message: String,
    },
}

/// One line in a panel.
#[derive(Debug, Clone, Copy)]
pub struct Series<'a> {
    /// Legend text.
    pub label: &'a str,
    /// Points `(x, y)`; non-finite points are skipped.
    pub points: &'a [(f64, f64)],
}

/// One plot area with its axes and lines.
#[derive(Debug, Clone)]
pub struct Panel<'a> {
    /// Panel caption.
    pub title: &'a str,
    /// X axis label, with unit.
    pub x_label: &'a str,
    /// Y axis label, with unit.
    pub y_label: &'a str,
    /// The lines.
    pub series: Vec<Series<'a>>,
    /// Logarithmic x axis.
    pub log_x: bool,
    /// Logarithmic y axis.
    pub log_y: bool,
}

impl<'a> Panel<'a> {
    /// A panel with linear axes.
    pub fn new(
        title: &'a str,
        x_label: &'a str,
        y_label: &'a str,
        series: Vec<Series<'a>>,
    ) -> Self {
        Self {
            title,
            x_label,
            y_label,
            series,
            log_x: false,
            log_y: false,
        }
    }
}

pub(crate) fn register_font() -> Result<(), PlotError> {
    static DONE: OnceLock<bool> = OnceLock::new();
    let ok = *DONE.get_or_init(|| {
        plotters::style::register_font(FONT_FAMILY, FontStyle::Normal, FONT_TTF).is_ok()
    });
    ok.then_some(()).ok_or(PlotError::Font)
}

/// Distinguishable line colours (Tableau 10), cycled.
const COLOURS: [RGBColor; 10] = [
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

/// Data bounds of a panel over the points that can be drawn on its axes.
fn bounds(panel: &Panel) -> Option<((f64, f64), (f64, f64))> {
    let mut x = (f64::INFINITY, f64::NEG_INFINITY);
    let mut y = (f64::INFINITY, f64::NEG_INFINITY);
    for s in &panel.series {
        for &(px, py) in s.points {
            if !px.is_finite() || !py.is_finite() {
                continue;
            }
            if (panel.log_x && px <= 0.0) || (panel.log_y && py <= 0.0) {
                continue;
            }
            x = (x.0.min(px), x.1.max(px));
            y = (y.0.min(py), y.1.max(py));
        }
    }
    (x.0 <= x.1).then_some((x, y))
}

/// Widens a range so a flat line still gets a visible axis, with a margin on linear axes.
fn pad(lo: f64, hi: f64, log: bool, margin: bool) -> (f64, f64) {
    if log {
        if hi / lo < 1.0 + 1e-9 {
            (lo / 2.0, hi * 2.0)
        } else {
            (lo, hi)
        }
    } else {
        let span = hi - lo;
        let span = if span > 1e-12 * hi.abs().max(1.0) {
            span
        } else {
            hi.abs().max(1.0) * 0.01
        };
        let m = if margin { 0.05 * span } else { 0.0 };
        if span == hi - lo {
            (lo - m, hi + m)
        } else {
            (lo - span / 2.0 - m, hi + span / 2.0 + m)
        }
    }
}

/// Writes a figure: `panels` stacked vertically under `title`, as a PNG at `path`.
pub fn write_png(path: &Path, title: &str, panels: &[Panel]) -> Result<(), PlotError> {
    if panels.is_empty() {
        return Err(PlotError::NoPanels);
    }
    register_font()?;
    let backend_err = |e: &dyn std::fmt::Display| PlotError::Backend {
        path: path.display().to_string(),
        message: e.to_string(),
    };
    let height = TITLE_HEIGHT_PX + PANEL_HEIGHT_PX * panels.len() as u32;
    let root = BitMapBackend::new(path, (WIDTH_PX, height)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| backend_err(&e))?;
    let root = root
        .titled(title, (FONT_FAMILY, 26).into_font())
        .map_err(|e| backend_err(&e))?;
    let areas = root.split_evenly((panels.len(), 1));
    for (area, panel) in areas.iter().zip(panels) {
        let ((x0, x1), (y0, y1)) =
            bounds(panel).ok_or_else(|| PlotError::NoData(panel.title.to_string()))?;
        let (x0, x1) = pad(x0, x1, panel.log_x, false);
        let (y0, y1) = pad(y0, y1, panel.log_y, true);
        let r = match (panel.log_x, panel.log_y) {
            (false, false) => draw_panel(area, panel, x0..x1, y0..y1),
            (true, false) => draw_panel(area, panel, (x0..x1).log_scale(), y0..y1),
            (false, true) => draw_panel(area, panel, x0..x1, (y0..y1).log_scale()),
            (true, true) => draw_panel(area, panel, (x0..x1).log_scale(), (y0..y1).log_scale()),
        };
        r.map_err(|e| backend_err(&e))?;
    }
    root.present().map_err(|e| backend_err(&e))?;
    Ok(())
}

/// A tick's value in at most four significant digits: a log axis's ticks are powers of
/// ten computed in floating point, which print as `9.999999999999999e-6` unrounded.
pub(crate) fn tick_label(v: f64) -> String {
    let a = v.abs();
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let trim = |s: String| {
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s
        }
    };
    if (1e-3..1e5).contains(&a) {
        let decimals = (3 - a.log10().floor() as i32).max(0) as usize;
        trim(format!("{v:.decimals$}"))
    } else {
        let s = format!("{v:.3e}");
        let (mantissa, exponent) = s.split_once('e').unwrap_or((&s, "0"));
        format!("{}e{exponent}", trim(mantissa.to_string()))
    }
}

fn draw_panel<DB, X, Y>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    panel: &Panel,
    x_spec: X,
    y_spec: Y,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>>
where
    DB: DrawingBackend,
    X: AsRangedCoord<Value = f64>,
    Y: AsRangedCoord<Value = f64>,
    X::CoordDescType: ValueFormatter<f64>,
    Y::CoordDescType: ValueFormatter<f64>,
{
    let mut chart = ChartBuilder::on(area)
        .caption(panel.title, (FONT_FAMILY, 20).into_font())
        .margin(12)
        .x_label_area_size(44)
        .y_label_area_size(90)
        .build_cartesian_2d(x_spec, y_spec)?;
    chart
        .configure_mesh()
        .x_desc(panel.x_label)
        .y_desc(panel.y_label)
        .x_label_formatter(&|v| tick_label(*v))
        .y_label_formatter(&|v| tick_label(*v))
        .label_style((FONT_FAMILY, 15).into_font())
        .axis_desc_style((FONT_FAMILY, 16).into_font())
        .light_line_style(RGBColor(235, 235, 235))
        .draw()?;
    for (i, s) in panel.series.iter().enumerate() {
        let colour = COLOURS[i % COLOURS.len()];
        let (log_x, log_y) = (panel.log_x, panel.log_y);
        let pts = s.points.iter().copied().filter(move |&(x, y)| {
            x.is_finite() && y.is_finite() && (!log_x || x > 0.0) && (!log_y || y > 0.0)
        });
        chart
            .draw_series(LineSeries::new(pts, colour.stroke_width(2)))?
            .label(s.label)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(3))
            });
    }
    if panel.series.iter().any(|s| !s.label.is_empty()) {
        legend(&mut chart, SeriesLabelPosition::UpperRight, 15)?;
    }
    Ok(())
}

/// Maps a plotters backend error to a [`PlotError`] naming the figure at `path`.
pub fn backend_err(path: &Path) -> impl Fn(&dyn std::fmt::Display) -> PlotError + '_ {
    move |e| PlotError::Backend {
        path: path.display().to_string(),
        message: e.to_string(),
    }
}

/// The figures' font (the bundled DejaVu Sans) at `size` pixels.
pub fn font(size: u32) -> TextStyle<'static> {
    (FONT_FAMILY, size).into_font().into()
}

/// Draws `chart`'s legend at `position`: one look for every figure (white, bordered
/// box, `size`-pixel labels).
pub fn legend<'a, DB: DrawingBackend + 'a, CT: plotters::coord::CoordTranslate>(
    chart: &mut ChartContext<'a, DB, CT>,
    position: SeriesLabelPosition,
    size: u32,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    chart
        .configure_series_labels()
        .position(position)
        .label_font(font(size))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tick_labels_are_rounded_to_four_significant_digits() {
        for (v, want) in [
            (9.999999999999999e-6, "1e-5"),
            (3.1622776601683795e-7, "3.162e-7"),
            (0.1 + 0.2, "0.3"),
            (1500.0, "1500"),
            (12.5, "12.5"),
            (-0.25, "-0.25"),
            (2.0e6, "2e6"),
            (0.0, "0"),
        ] {
            assert_eq!(tick_label(v), want, "{v:e}");
        }
    }

    #[test]
    fn writes_a_png_with_linear_and_log_panels() {
        let dir = std::env::temp_dir().join(format!("oils-plot-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("t.png");
        let a: Vec<(f64, f64)> = (1..200).map(|i| (i as f64, (i as f64).sqrt())).collect();
        let flat: Vec<(f64, f64)> = (0..10).map(|i| (i as f64, 3.0)).collect();
        let mut log = Panel::new(
            "log",
            "x [-]",
            "y [-]",
            vec![Series {
                label: "sqrt",
                points: &a,
            }],
        );
        log.log_x = true;
        log.log_y = true;
        let lin = Panel::new(
            "flat",
            "x [-]",
            "y [-]",
            vec![Series {
                label: "3",
                points: &flat,
            }],
        );
        write_png(&path, "test figure", &[log, lin]).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(&bytes[1..4], b"PNG");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn empty_inputs_are_errors() {
        let p = std::path::Path::new("/nonexistent/x.png");
        assert!(matches!(write_png(p, "t", &[]), Err(PlotError::NoPanels)));
        let nan = [(f64::NAN, 1.0)];
        let panel = Panel::new(
            "nan",
            "x",
            "y",
            vec![Series {
                label: "",
                points: &nan,
            }],
        );
        assert!(matches!(
            write_png(p, "t", &[panel]),
            Err(PlotError::NoData(_))
        ));
    }
}
