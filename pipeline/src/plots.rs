//! Figures for reports (PNG, plotters with an embedded DejaVu Sans font; see
//! assets/fonts/DejaVu-LICENSE.txt). Every figure is written atomically.
use crate::error::CliError;
use camsim_core::exr_io::write_atomically;
use plotters::prelude::*;
use std::path::Path;
use std::sync::Once;

static FONT: Once = Once::new();

/// Register the embedded font under the family name "sans-serif" (idempotent).
pub fn init_fonts() {
    FONT.call_once(|| {
        let bytes: &'static [u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");
        let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, bytes);
    });
}

const W: u32 = 720;
const H: u32 = 480;

fn draw<F>(path: &Path, f: F) -> Result<(), CliError>
where
    F: FnOnce(DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>) -> Result<(), String>,
{
    init_fonts();
    write_atomically(path, |tmp| -> Result<(), std::io::Error> {
        // plotters picks the encoder from the extension: keep ".png" on the temporary name
        let tmp_png = tmp.with_extension("tmp.png");
        let res = {
            let root = BitMapBackend::new(&tmp_png, (W, H)).into_drawing_area();
            root.fill(&WHITE)
                .map_err(|e| std::io::Error::other(e.to_string()))?;
            f(root.clone()).map_err(std::io::Error::other)?;
            root.present()
                .map_err(|e| std::io::Error::other(e.to_string()))
        };
        res?;
        std::fs::rename(&tmp_png, tmp)
    })
    .map_err(|e| CliError::output(path, e))
}

fn e<E: std::fmt::Display>(x: E) -> String {
    x.to_string()
}

fn range(v: impl Iterator<Item = f64>, pad: f64) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for x in v.filter(|x| x.is_finite()) {
        lo = lo.min(x);
        hi = hi.max(x);
    }
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    if hi - lo < 1e-12 {
        return (lo - 0.5, hi + 0.5);
    }
    let d = (hi - lo) * pad;
    (lo - d, hi + d)
}

/// A bar chart, one bar per label.
pub fn bar_chart(
    path: &Path,
    title: &str,
    labels: &[String],
    values: &[f64],
    y_label: &str,
) -> Result<(), CliError> {
    let (lo, hi) = range(values.iter().copied().chain([0.0]), 0.05);
    draw(path, |root| {
        let mut ch = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 22))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(0f64..values.len() as f64, lo..hi)
            .map_err(e)?;
        ch.configure_mesh()
            .y_desc(y_label)
            .x_desc("patch")
            .x_labels(values.len().min(24))
            .x_label_formatter(&|x| labels.get(x.floor() as usize).cloned().unwrap_or_default())
            .disable_x_mesh()
            .draw()
            .map_err(e)?;
        ch.draw_series(values.iter().enumerate().map(|(i, v)| {
            Rectangle::new(
                [(i as f64 + 0.15, 0.0), (i as f64 + 0.85, *v)],
                BLUE.mix(0.7).filled(),
            )
        }))
        .map_err(e)?;
        Ok(())
    })
}

/// A histogram of `values` with `bins` bins.
pub fn histogram(
    path: &Path,
    title: &str,
    values: &[f64],
    bins: usize,
    x_label: &str,
) -> Result<(), CliError> {
    let (lo, hi) = range(values.iter().copied().chain([0.0]), 0.0);
    let w = (hi - lo) / bins as f64;
    let mut counts = vec![0usize; bins];
    for v in values {
        let b = (((v - lo) / w) as usize).min(bins - 1);
        counts[b] += 1;
    }
    let ymax = *counts.iter().max().unwrap_or(&1) as f64 * 1.1 + 1.0;
    draw(path, |root| {
        let mut ch = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 22))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(50)
            .build_cartesian_2d(lo..hi, 0f64..ymax)
            .map_err(e)?;
        ch.configure_mesh()
            .x_desc(x_label)
            .y_desc("count")
            .draw()
            .map_err(e)?;
        ch.draw_series(counts.iter().enumerate().map(|(i, c)| {
            let x0 = lo + i as f64 * w;
            Rectangle::new(
                [(x0, 0.0), (x0 + w * 0.95, *c as f64)],
                RED.mix(0.6).filled(),
            )
        }))
        .map_err(e)?;
        Ok(())
    })
}

/// A scatter plot; points take `colors` when given; `diagonal` draws y = x.
pub fn scatter(
    path: &Path,
    title: &str,
    x: &[f64],
    y: &[f64],
    colors: Option<&[[u8; 3]]>,
    axis_labels: (&str, &str),
    diagonal: bool,
) -> Result<(), CliError> {
    let (lo, hi) = range(x.iter().chain(y.iter()).copied(), 0.05);
    draw(path, |root| {
        let mut ch = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 22))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(lo..hi, lo..hi)
            .map_err(e)?;
        ch.configure_mesh()
            .x_desc(axis_labels.0)
            .y_desc(axis_labels.1)
            .draw()
            .map_err(e)?;
        if diagonal {
            ch.draw_series(LineSeries::new([(lo, lo), (hi, hi)], BLACK.mix(0.5)))
                .map_err(e)?;
        }
        ch.draw_series(x.iter().zip(y).enumerate().map(|(i, (a, b))| {
            let c = colors
                .and_then(|c| c.get(i))
                .map(|c| RGBColor(c[0], c[1], c[2]))
                .unwrap_or(BLUE);
            Circle::new((*a, *b), 6, ShapeStyle::from(&c).filled())
        }))
        .map_err(e)?;
        ch.draw_series(
            x.iter()
                .zip(y)
                .map(|(a, b)| Circle::new((*a, *b), 6, BLACK.stroke_width(1))),
        )
        .map_err(e)?;
        Ok(())
    })
}

/// Line plot of named series.
pub fn line_plot(
    path: &Path,
    title: &str,
    series: &[(String, Vec<(f64, f64)>)],
    axis_labels: (&str, &str),
) -> Result<(), CliError> {
    let (x0, x1) = range(series.iter().flat_map(|s| s.1.iter().map(|p| p.0)), 0.0);
    let (y0, y1) = range(series.iter().flat_map(|s| s.1.iter().map(|p| p.1)), 0.05);
    let palette = [BLUE, RED, GREEN, MAGENTA, CYAN, BLACK];
    draw(path, |root| {
        let mut ch = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 22))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(e)?;
        ch.configure_mesh()
            .x_desc(axis_labels.0)
            .y_desc(axis_labels.1)
            .draw()
            .map_err(e)?;
        for (i, (name, pts)) in series.iter().enumerate() {
            let c = palette[i % palette.len()];
            ch.draw_series(LineSeries::new(pts.iter().copied(), c.stroke_width(2)))
                .map_err(e)?
                .label(name.clone())
                .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], c.stroke_width(2)));
        }
        if series.len() > 1 {
            ch.configure_series_labels()
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .draw()
                .map_err(e)?;
        }
        Ok(())
    })
}

/// Write an 8-bit RGB image (row-major, 3 bytes per pixel) as PNG, atomically.
pub fn rgb8_png(path: &Path, rgb: &[u8], rows: usize, cols: usize) -> Result<(), CliError> {
    write_atomically(path, |tmp| -> Result<(), std::io::Error> {
        let f = std::io::BufWriter::new(std::fs::File::create(tmp)?);
        let mut enc = png::Encoder::new(f, cols as u32, rows as u32);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut w = enc.write_header().map_err(std::io::Error::other)?;
        w.write_image_data(rgb).map_err(std::io::Error::other)?;
        w.finish().map_err(std::io::Error::other)
    })
    .map_err(|e| CliError::output(path, e))
}

/// Facts about a PNG figure used by tests: size and number of distinct colours.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FigureCheck {
    /// width
    pub width: u32,
    /// height
    pub height: u32,
    /// distinct RGB colours
    pub distinct_colours: usize,
    /// fraction of pixels that are not white
    pub non_white_per_mille: u32,
}

/// Decode a PNG and summarise it (to check a figure really shows something).
pub fn check_figure(path: &Path) -> Result<FigureCheck, CliError> {
    let f = std::fs::File::open(path).map_err(|e| CliError::input(path, e))?;
    let mut r = png::Decoder::new(std::io::BufReader::new(f))
        .read_info()
        .map_err(|e| CliError::input(path, e))?;
    let mut buf = vec![0u8; r.output_buffer_size().unwrap_or(0)];
    let info = r
        .next_frame(&mut buf)
        .map_err(|e| CliError::input(path, e))?;
    let ch = info.color_type.samples();
    let px = &buf[..info.buffer_size()];
    let mut set = std::collections::HashSet::new();
    let mut non_white = 0usize;
    let n = px.len() / ch;
    for p in px.chunks_exact(ch) {
        let rgb = if ch >= 3 {
            [p[0], p[1], p[2]]
        } else {
            [p[0], p[0], p[0]]
        };
        if rgb != [255, 255, 255] {
            non_white += 1;
        }
        set.insert(rgb);
    }
    Ok(FigureCheck {
        width: info.width,
        height: info.height,
        distinct_colours: set.len(),
        non_white_per_mille: (non_white * 1000 / n.max(1)) as u32,
    })
}

/// One curve with an uncertainty band for [`band_plot`].
#[derive(Debug, Clone, PartialEq)]
pub struct BandSeries {
    /// Legend name.
    pub name: String,
    /// RGB colour.
    pub colour: [u8; 3],
    /// Points (x, y, lower, upper); a band is drawn where lower < upper.
    pub points: Vec<(f64, f64, f64, f64)>,
    /// Draw dashed (e.g. a reference curve).
    pub dashed: bool,
}

/// Curves with shaded uncertainty bands (e.g. fitted spectral efficiencies ± 1σ).
pub fn band_plot(
    path: &Path,
    title: &str,
    series: &[BandSeries],
    axis_labels: (&str, &str),
) -> Result<(), CliError> {
    let (x0, x1) = range(
        series.iter().flat_map(|s| s.points.iter().map(|p| p.0)),
        0.0,
    );
    let (y0, y1) = range(
        series
            .iter()
            .flat_map(|s| s.points.iter().flat_map(|p| [p.1, p.2, p.3])),
        0.05,
    );
    draw(path, |root| {
        let mut ch = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 22))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(e)?;
        ch.configure_mesh()
            .x_desc(axis_labels.0)
            .y_desc(axis_labels.1)
            .draw()
            .map_err(e)?;
        for s in series {
            let c = RGBColor(s.colour[0], s.colour[1], s.colour[2]);
            if s.points.iter().any(|p| p.2 < p.3) {
                let poly: Vec<(f64, f64)> = s
                    .points
                    .iter()
                    .map(|p| (p.0, p.3))
                    .chain(s.points.iter().rev().map(|p| (p.0, p.2)))
                    .collect();
                ch.draw_series(std::iter::once(Polygon::new(poly, c.mix(0.2).filled())))
                    .map_err(e)?;
            }
            let pts: Vec<(f64, f64)> = s.points.iter().map(|p| (p.0, p.1)).collect();
            let style = c.stroke_width(2);
            let legend = move |(x, y): (i32, i32)| PathElement::new([(x, y), (x + 20, y)], style);
            if s.dashed {
                // dashes: every other segment of a 4× refined polyline
                let mut segs = Vec::new();
                for w in pts.windows(2) {
                    for k in 0..4 {
                        if k % 2 == 0 {
                            let t0 = k as f64 / 4.0;
                            let t1 = (k + 1) as f64 / 4.0;
                            let p = |t: f64| {
                                (
                                    w[0].0 + t * (w[1].0 - w[0].0),
                                    w[0].1 + t * (w[1].1 - w[0].1),
                                )
                            };
                            segs.push(PathElement::new([p(t0), p(t1)], style));
                        }
                    }
                }
                ch.draw_series(segs)
                    .map_err(e)?
                    .label(s.name.clone())
                    .legend(legend);
            } else {
                ch.draw_series(LineSeries::new(pts, style))
                    .map_err(e)?
                    .label(s.name.clone())
                    .legend(legend);
            }
        }
        ch.configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(e)?;
        Ok(())
    })
}
