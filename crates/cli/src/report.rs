//! The run report: one self-contained HTML file (`out/report.html`) with stage
//! timings, metric tables, a contact sheet of frames with mask overlays, loss /
//! PSNR curves (drawn with `plotters` as inline SVG) and before/after renders.
//! Images are embedded as base64 PNG data URIs so the file stands alone.

use anyhow::{Context, Result};
use base64::Engine;
use plotters::prelude::*;
use std::fmt::Write as _;
use std::path::Path;

/// A table of strings with a caption.
#[derive(Debug, Clone, Default)]
pub struct Table {
    pub caption: String,
    pub header: Vec<String>,
    pub rows: Vec<Vec<String>>,
}

/// A named series of (x, y) points for a line chart.
#[derive(Debug, Clone, Default)]
pub struct Series {
    pub name: String,
    pub points: Vec<(f64, f64)>,
}

/// One line chart.
#[derive(Debug, Clone, Default)]
pub struct Chart {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub series: Vec<Series>,
}

/// An image with a caption, already encoded as PNG bytes.
#[derive(Debug, Clone)]
pub struct Figure {
    pub caption: String,
    pub png: Vec<u8>,
}

/// Everything the report shows.
#[derive(Debug, Clone, Default)]
pub struct Report {
    pub title: String,
    /// (stage, seconds)
    pub timings: Vec<(String, f64)>,
    pub tables: Vec<Table>,
    pub charts: Vec<Chart>,
    /// Contact sheet: frames with mask overlays.
    pub contact_sheet: Vec<Figure>,
    /// Before/after renders, shown in rows of figures.
    pub renders: Vec<Vec<Figure>>,
}

/// Encode an RGB8 image as PNG bytes.
pub fn png_rgb8(img: &image::RgbImage) -> Result<Vec<u8>> {
    let mut buf = std::io::Cursor::new(Vec::new());
    img.write_to(&mut buf, image::ImageFormat::Png)
        .context("encoding PNG")?;
    Ok(buf.into_inner())
}

/// Tint the pixels a mask marks as moving (mask value < 128 in the masks/
/// convention: 0 = moving) in red, half transparent.
pub fn overlay_mask(frame: &image::RgbImage, keep_mask: &image::GrayImage) -> image::RgbImage {
    let mut out = frame.clone();
    if keep_mask.dimensions() != frame.dimensions() {
        return out;
    }
    for (x, y, p) in out.enumerate_pixels_mut() {
        if keep_mask.get_pixel(x, y)[0] < 128 {
            p[0] = ((p[0] as u16 + 255) / 2) as u8;
            p[1] /= 2;
            p[2] /= 2;
        }
    }
    out
}

/// Downscale an image so its width is at most `max_w` (thumbnails).
pub fn thumbnail(img: &image::RgbImage, max_w: u32) -> image::RgbImage {
    if img.width() <= max_w {
        return img.clone();
    }
    let h = ((img.height() as f64) * max_w as f64 / img.width() as f64)
        .round()
        .max(1.0) as u32;
    image::imageops::resize(img, max_w, h, image::imageops::FilterType::Triangle)
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// Draw a chart as an SVG string.
pub fn chart_svg(chart: &Chart) -> Result<String> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (640, 320)).into_drawing_area();
        root.fill(&WHITE)
            .map_err(|e| anyhow::anyhow!("chart: {e}"))?;
        let pts = chart
            .series
            .iter()
            .flat_map(|s| s.points.iter())
            .filter(|(x, y)| x.is_finite() && y.is_finite());
        let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        for (x, y) in pts {
            x0 = x0.min(*x);
            x1 = x1.max(*x);
            y0 = y0.min(*y);
            y1 = y1.max(*y);
        }
        if x0 > x1 {
            (x0, x1, y0, y1) = (0.0, 1.0, 0.0, 1.0);
        }
        if x1 - x0 < 1e-12 {
            x1 = x0 + 1.0;
        }
        let pad = ((y1 - y0) * 0.05).max(1e-6);
        let mut cc = ChartBuilder::on(&root)
            .caption(&chart.title, ("sans-serif", 18))
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(55)
            .build_cartesian_2d(x0..x1, (y0 - pad)..(y1 + pad))
            .map_err(|e| anyhow::anyhow!("chart: {e}"))?;
        cc.configure_mesh()
            .x_desc(chart.x_label.as_str())
            .y_desc(chart.y_label.as_str())
            .draw()
            .map_err(|e| anyhow::anyhow!("chart: {e}"))?;
        for (i, s) in chart.series.iter().enumerate() {
            let color = Palette99::pick(i).to_rgba();
            cc.draw_series(LineSeries::new(
                s.points
                    .iter()
                    .copied()
                    .filter(|(x, y)| x.is_finite() && y.is_finite()),
                color.stroke_width(2),
            ))
            .map_err(|e| anyhow::anyhow!("chart: {e}"))?
            .label(s.name.clone())
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2))
            });
        }
        if chart.series.len() > 1 {
            cc.configure_series_labels()
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .draw()
                .map_err(|e| anyhow::anyhow!("chart: {e}"))?;
        }
        root.present().map_err(|e| anyhow::anyhow!("chart: {e}"))?;
    }
    Ok(svg)
}

fn figure_html(f: &Figure) -> String {
    let b64 = base64::engine::general_purpose::STANDARD.encode(&f.png);
    format!(
        "<figure><img src=\"data:image/png;base64,{b64}\" alt=\"{0}\"><figcaption>{0}</figcaption></figure>",
        escape(&f.caption)
    )
}

impl Report {
    /// Render the whole report as one HTML document.
    pub fn to_html(&self) -> Result<String> {
        let mut h = String::new();
        let title = escape(&self.title);
        let _ = write!(
            h,
            "<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>{title}</title><style>\
body{{font-family:sans-serif;margin:2em;color:#222}}table{{border-collapse:collapse;margin:1em 0}}\
td,th{{border:1px solid #bbb;padding:4px 10px;text-align:right}}th{{background:#eee}}\
td:first-child,th:first-child{{text-align:left}}figure{{display:inline-block;margin:4px}}\
figure img{{max-width:320px;display:block}}figcaption{{font-size:12px}}.row{{display:flex;flex-wrap:wrap}}\
</style></head><body><h1>{title}</h1>"
        );
        if !self.timings.is_empty() {
            let total: f64 = self.timings.iter().map(|t| t.1).sum();
            h.push_str("<h2>Stage timings</h2><table id=\"timings\"><tr><th>stage</th><th>seconds</th></tr>");
            for (stage, s) in &self.timings {
                let _ = write!(h, "<tr><td>{}</td><td>{s:.1}</td></tr>", escape(stage));
            }
            let _ = write!(h, "<tr><th>total</th><th>{total:.1}</th></tr></table>");
        }
        for t in &self.tables {
            let _ = write!(
                h,
                "<h2>{}</h2><table class=\"metrics\"><tr>",
                escape(&t.caption)
            );
            for c in &t.header {
                let _ = write!(h, "<th>{}</th>", escape(c));
            }
            h.push_str("</tr>");
            for r in &t.rows {
                h.push_str("<tr>");
                for c in r {
                    let _ = write!(h, "<td>{}</td>", escape(c));
                }
                h.push_str("</tr>");
            }
            h.push_str("</table>");
        }
        if !self.charts.is_empty() {
            h.push_str("<h2>Training curves</h2><div class=\"row\">");
            for c in &self.charts {
                let _ = write!(h, "<div class=\"chart\">{}</div>", chart_svg(c)?);
            }
            h.push_str("</div>");
        }
        if !self.contact_sheet.is_empty() {
            h.push_str(
                "<h2>Frames and motion masks (red = moving)</h2><div class=\"row\" id=\"contact\">",
            );
            for f in &self.contact_sheet {
                h.push_str(&figure_html(f));
            }
            h.push_str("</div>");
        }
        if !self.renders.is_empty() {
            h.push_str("<h2>Held-out views</h2>");
            for row in &self.renders {
                h.push_str("<div class=\"row\">");
                for f in row {
                    h.push_str(&figure_html(f));
                }
                h.push_str("</div>");
            }
        }
        h.push_str("</body></html>\n");
        Ok(h)
    }

    /// Write the report atomically.
    pub fn write(&self, path: &Path) -> Result<()> {
        let html = self.to_html()?;
        loader::io::write_atomic(path, |w| {
            w.write_all(html.as_bytes())
                .map_err(|e| loader::LoaderError::io(path, e))
        })
        .with_context(|| format!("writing report {}", path.display()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn report_is_self_contained_and_escaped() {
        let img = image::RgbImage::from_pixel(8, 4, image::Rgb([10, 200, 30]));
        let mut mask = image::GrayImage::from_pixel(8, 4, image::Luma([255]));
        mask.put_pixel(1, 1, image::Luma([0]));
        let over = overlay_mask(&img, &mask);
        assert_eq!(over.get_pixel(1, 1).0, [132, 100, 15]);
        assert_eq!(over.get_pixel(0, 0).0, [10, 200, 30]);
        let r = Report {
            title: "a <b> & c".into(),
            timings: vec![("mask".into(), 1.5), ("train".into(), 2.0)],
            tables: vec![Table {
                caption: "t".into(),
                header: vec!["x".into()],
                rows: vec![vec!["1".into()]],
            }],
            charts: vec![Chart {
                title: "loss".into(),
                x_label: "step".into(),
                y_label: "L1".into(),
                series: vec![Series {
                    name: "a".into(),
                    points: vec![(0.0, 1.0), (1.0, 0.5), (2.0, f64::NAN)],
                }],
            }],
            contact_sheet: vec![Figure {
                caption: "f".into(),
                png: png_rgb8(&over).unwrap(),
            }],
            renders: vec![],
        };
        let html = r.to_html().unwrap();
        assert!(html.contains("a &lt;b&gt; &amp; c"));
        assert!(html.contains("<svg"));
        assert!(html.contains("data:image/png;base64,iVBORw0KGgo"));
        assert!(html.contains("<th>total</th><th>3.5</th>"));
        // No external resources.
        assert!(!html.contains("src=\"http"));
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("report.html");
        r.write(&p).unwrap();
        assert_eq!(std::fs::read_to_string(&p).unwrap(), html);
    }
}
