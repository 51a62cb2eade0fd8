//! [`HtmlReport`]: a page built block by block.

use std::io::Write;
use std::path::Path;

use base64::Engine;

use crate::error::Result;
use crate::file::write_atomic;
use crate::render::png_bytes;
use image::RgbImage;

/// Escapes `&`, `<`, `>`, `"` and `'` for HTML text and attribute values.
///
/// ```
/// assert_eq!(olmap::report::escape("a<b & \"c\""), "a&lt;b &amp; &quot;c&quot;");
/// ```
pub fn escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

/// An HTML report: a title and blocks in order. Nothing refers outside the file.
///
/// ```
/// use olmap::report::HtmlReport;
/// use olmap::render::RgbImage;
/// let mut r = HtmlReport::new("Run <1>");
/// r.heading("Parameters");
/// r.key_values(&[("resolution", "0.1 m".to_string())]);
/// r.image("a picture", &RgbImage::new(2, 2)).unwrap();
/// let html = r.to_html();
/// assert!(html.contains("<title>Run &lt;1&gt;</title>"));
/// assert!(html.contains("src=\"data:image/png;base64,"));
/// ```
#[derive(Debug, Clone, Default)]
pub struct HtmlReport {
    title: String,
    body: String,
    images: usize,
}

impl HtmlReport {
    /// An empty report.
    pub fn new(title: impl Into<String>) -> Self {
        HtmlReport {
            title: title.into(),
            body: String::new(),
            images: 0,
        }
    }

    /// Images added so far.
    pub fn images(&self) -> usize {
        self.images
    }

    /// A section heading.
    pub fn heading(&mut self, text: &str) -> &mut Self {
        self.body.push_str(&format!("<h2>{}</h2>\n", escape(text)));
        self
    }

    /// A paragraph of plain text.
    pub fn paragraph(&mut self, text: &str) -> &mut Self {
        self.body.push_str(&format!("<p>{}</p>\n", escape(text)));
        self
    }

    /// A two-column table of names and values.
    pub fn key_values(&mut self, rows: &[(&str, String)]) -> &mut Self {
        let rows: Vec<Vec<String>> = rows
            .iter()
            .map(|(k, v)| vec![k.to_string(), v.clone()])
            .collect();
        self.table(&[], &rows)
    }

    /// A table with a header row (none when `header` is empty).
    pub fn table(&mut self, header: &[&str], rows: &[Vec<String>]) -> &mut Self {
        self.body.push_str("<table>\n");
        if !header.is_empty() {
            self.body.push_str("<tr>");
            for h in header {
                self.body.push_str(&format!("<th>{}</th>", escape(h)));
            }
            self.body.push_str("</tr>\n");
        }
        for row in rows {
            self.body.push_str("<tr>");
            for c in row {
                self.body.push_str(&format!("<td>{}</td>", escape(c)));
            }
            self.body.push_str("</tr>\n");
        }
        self.body.push_str("</table>\n");
        self
    }

    /// A JSON value shown pretty-printed (e.g. the run's parameters).
    pub fn json(&mut self, value: &impl serde::Serialize) -> &mut Self {
        let text = serde_json::to_string_pretty(value).unwrap_or_default();
        self.body
            .push_str(&format!("<pre>{}</pre>\n", escape(&text)));
        self
    }

    /// An image with a caption, inlined as a PNG `data:` URI.
    pub fn image(&mut self, caption: &str, image: &RgbImage) -> Result<&mut Self> {
        let png = png_bytes(image)?;
        let b64 = base64::engine::general_purpose::STANDARD.encode(png);
        self.body.push_str(&format!(
            "<figure><img alt=\"{0}\" src=\"data:image/png;base64,{1}\"><figcaption>{0}</figcaption></figure>\n",
            escape(caption),
            b64
        ));
        self.images += 1;
        Ok(self)
    }

    /// The whole page.
    pub fn to_html(&self) -> String {
        format!(
            "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>{t}</title>\n<style>\n\
             body {{ font-family: sans-serif; margin: 2em; max-width: 1100px; }}\n\
             table {{ border-collapse: collapse; margin: 0.5em 0 1em; }}\n\
             td, th {{ border: 1px solid #bbb; padding: 3px 8px; text-align: left; }}\n\
             th {{ background: #eee; }}\n\
             figure {{ display: inline-block; margin: 0.5em 1em 1em 0; vertical-align: top; }}\n\
             img {{ max-width: 100%; min-width: 420px; border: 1px solid #ccc; image-rendering: pixelated; }}\n\
             figcaption {{ font-size: 0.9em; color: #444; max-width: 520px; }}\n\
             pre {{ background: #f6f6f6; padding: 0.5em; overflow-x: auto; }}\n\
             </style>\n</head>\n<body>\n<h1>{t}</h1>\n{b}</body>\n</html>\n",
            t = escape(&self.title),
            b = self.body
        )
    }

    /// Writes the page atomically.
    pub fn write(&self, path: impl AsRef<Path>) -> Result<()> {
        let html = self.to_html();
        write_atomic(path.as_ref(), "HTML report", |w| {
            w.write_all(html.as_bytes())
        })
    }
}
