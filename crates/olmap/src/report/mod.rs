//! Self-contained HTML reports: one file with the run's parameters, timings, tables and
//! images inlined as base64 `data:` URIs, for `olmap map --report`, `olmap team` and
//! `olmap demo`. [`HtmlReport`] builds a page block by block; [`sections`] holds the blocks
//! the map and team reports share. The typed JSON reports themselves live with their
//! pipelines ([`crate::mapping::MapReport`], [`crate::team::TeamReport`]).

mod html;
pub mod sections;

pub use html::{escape, HtmlReport};
