//! The small pieces the report's sections are written with: a note, a figure, tables,
//! signed numbers and colour swatches.

use maud::{Markup, PreEscaped, html};

use super::swatch;
use chromacal_color::Xyz;

pub fn figure(id: &str, svg: &str, caption: &str) -> Markup {
    html! {
        figure id=(id) { (PreEscaped(svg)) figcaption { (caption) } }
    }
}

pub fn note(text: &str) -> Markup {
    html! { p.note { (text) } }
}

/// Figures to the right, so that their decimals line up; words to the left.
pub fn is_numeric(cell: &str) -> bool {
    let trimmed = cell.trim_end_matches(" %").trim_end_matches(" K");
    trimmed.parse::<f64>().is_ok() || cell == "–"
}

/// A table with a header row.
pub fn table(headers: &[&str], rows: &[Vec<String>]) -> Markup {
    html! {
        table {
            tr { @for h in headers { th { (h) } } }
            @for row in rows {
                tr { @for cell in row { td.text[!is_numeric(cell)] { (cell) } } }
            }
        }
    }
}

/// A two-column table of names and values.
pub fn facts(rows: &[(&str, String)]) -> Markup {
    html! {
        table {
            @for (name, value) in rows {
                tr { th { (name) } td style="text-align:left" { (value) } }
            }
        }
    }
}

/// `v` with its sign and `decimals` decimals, and a value that rounds to zero as an
/// unsigned zero (not "-0.00").
pub fn signed(v: f64, decimals: usize) -> String {
    let text = format!("{v:+.decimals$}");
    if text[1..].chars().all(|c| c == '0' || c == '.') {
        text[1..].to_string()
    } else {
        text
    }
}

/// `#rrggbb` of a swatch showing `xyz` against `white`.
pub fn hex(xyz: &Xyz, white: &Xyz) -> String {
    let [r, g, b] = swatch(xyz, white);
    format!("#{r:02x}{g:02x}{b:02x}")
}

pub fn swatch_span(xyz: &Xyz, white: &Xyz) -> Markup {
    html! { span.swatch style={ "background:" (hex(xyz, white)) } {} }
}
