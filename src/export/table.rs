//! Tables written in two forms from one definition: Markdown (the dataset card, `stats.md`) and HTML
//! (`index.html`), so the two never disagree.

use std::fmt::Write as _;

/// A table: a header, and rows of cells as text.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Table {
    /// Column names.
    pub header: Vec<String>,
    /// Per column: right-aligned (numbers) or left-aligned (names).
    pub numeric: Vec<bool>,
    /// The rows, one cell per column.
    pub rows: Vec<Vec<String>>,
}

impl Table {
    /// An empty table with these columns, `(name, numeric)`.
    pub fn new(columns: &[(&str, bool)]) -> Table {
        Table {
            header: columns.iter().map(|c| c.0.to_string()).collect(),
            numeric: columns.iter().map(|c| c.1).collect(),
            rows: Vec::new(),
        }
    }

    /// Appends a row (one cell per column).
    pub fn push(&mut self, cells: Vec<String>) {
        debug_assert_eq!(cells.len(), self.header.len(), "one cell per column");
        self.rows.push(cells);
    }

    /// The table in GitHub Markdown (numbers right-aligned), ending with a newline.
    pub fn markdown(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(s, "| {} |", self.header.join(" | "));
        let rule: Vec<&str> = self.numeric.iter().map(|&n| if n { "---:" } else { "---" }).collect();
        let _ = writeln!(s, "|{}|", rule.join("|"));
        for r in &self.rows {
            let cells: Vec<String> = r.iter().map(|c| c.replace('|', "\\|")).collect();
            let _ = writeln!(s, "| {} |", cells.join(" | "));
        }
        s
    }

    /// The table as an HTML `<table>` (text escaped; numeric cells get `class="n"`).
    pub fn html(&self) -> String {
        let mut s = String::from("<table>\n<thead><tr>");
        for (h, &n) in self.header.iter().zip(&self.numeric) {
            let _ = write!(s, "<th{}>{}</th>", if n { " class=\"n\"" } else { "" }, escape_html(h));
        }
        s.push_str("</tr></thead>\n<tbody>\n");
        for r in &self.rows {
            s.push_str("<tr>");
            for (c, &n) in r.iter().zip(&self.numeric) {
                let _ = write!(s, "<td{}>{}</td>", if n { " class=\"n\"" } else { "" }, escape_html(c));
            }
            s.push_str("</tr>\n");
        }
        s.push_str("</tbody>\n</table>\n");
        s
    }
}

/// `text` with the five HTML special characters escaped (safe in element content and in quoted
/// attribute values).
pub fn escape_html(text: &str) -> String {
    let mut s = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => s.push_str("&amp;"),
            '<' => s.push_str("&lt;"),
            '>' => s.push_str("&gt;"),
            '"' => s.push_str("&quot;"),
            '\'' => s.push_str("&#39;"),
            _ => s.push(c),
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_table_two_forms() {
        let mut t = Table::new(&[("split", false), ("images", true)]);
        t.push(vec!["train".into(), "12".into()]);
        t.push(vec!["a|b <c>".into(), "3".into()]);
        assert_eq!(t.markdown(), "| split | images |\n|---|---:|\n| train | 12 |\n| a\\|b <c> | 3 |\n");
        let h = t.html();
        assert!(h.contains("<th>split</th><th class=\"n\">images</th>"), "{h}");
        assert!(h.contains("<tr><td>a|b &lt;c&gt;</td><td class=\"n\">3</td></tr>"), "{h}");
    }
}
