//! Self-contained HTML reports: one file with the run's parameters, timings, tables and
//! images inlined as base64 `data:` URIs, for `olmap map --report`, `olmap team` and
//! `olmap demo`.

mod html;

pub use html::{escape, HtmlReport};
