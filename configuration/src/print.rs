//! The resolved configuration as TOML, each key marked with where its
//! value came from: what `arcnav config` prints.

use toml_edit::{DocumentMut, Item, Table};

use crate::Resolved;

impl Resolved {
    /// The configuration as it is built, as TOML that reads back to the
    /// same configuration, every key followed by a comment saying whether
    /// its value is a default, came from a file or the command line, or
    /// was derived (and from what).
    pub fn to_toml_with_origins(&self) -> String {
        let text = self.effective().to_toml();
        let Ok(mut document) = text.parse::<DocumentMut>() else {
            // What `to_toml` wrote always parses; never lose the values.
            return text;
        };
        mark(self, "", document.as_table_mut());
        document.to_string()
    }
}

fn mark(resolved: &Resolved, prefix: &str, table: &mut Table) {
    for (key, item) in table.iter_mut() {
        let dotted = if prefix.is_empty() {
            key.get().to_owned()
        } else {
            format!("{prefix}.{}", key.get())
        };
        match item {
            Item::Table(inner) => mark(resolved, &dotted, inner),
            Item::Value(value) => {
                value
                    .decor_mut()
                    .set_suffix(format!("  # {}", resolved.origin(&dotted)));
            }
            Item::ArrayOfTables(array) => {
                let origin = resolved.origin(&dotted);
                for inner in array.iter_mut() {
                    inner
                        .decor_mut()
                        .set_prefix(format!("# {dotted}: {origin}\n"));
                }
            }
            Item::None => {}
        }
    }
}
