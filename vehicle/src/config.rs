//! Configuration errors and the checks every crate's `validate()` uses.
//!
//! Each crate owns its configuration struct (`serde(default,
//! deny_unknown_fields)`, `Default` with the documented defaults, and a
//! `validate()`); all of them report a bad value as a [`ConfigError`] naming
//! the key, so a user knows which line of their TOML to fix.

/// A configuration value that is out of range or contradicts another one.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("`{key}`: {reason}")]
pub struct ConfigError {
    /// Dotted key path, e.g. `vehicle.wheelbase_m`.
    pub key: String,
    /// What is wrong and what would be accepted.
    pub reason: String,
}

impl ConfigError {
    pub fn new(key: impl Into<String>, reason: impl Into<String>) -> Self {
        Self {
            key: key.into(),
            reason: reason.into(),
        }
    }

    /// Prefixes the key with the section the struct lives in
    /// (`wheelbase_m` → `vehicle.wheelbase_m`).
    #[must_use]
    pub fn within(mut self, section: &str) -> Self {
        self.key = format!("{section}.{}", self.key);
        self
    }
}

/// `value` must be finite and strictly positive.
pub fn positive(key: &str, value: f64) -> Result<(), ConfigError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(ConfigError::new(
            key,
            format!("is {value}, must be a finite number > 0"),
        ))
    }
}

/// `value` must be finite and not negative.
pub fn non_negative(key: &str, value: f64) -> Result<(), ConfigError> {
    if value.is_finite() && value >= 0.0 {
        Ok(())
    } else {
        Err(ConfigError::new(
            key,
            format!("is {value}, must be a finite number >= 0"),
        ))
    }
}

/// `value` must lie in the closed interval `[min, max]`.
pub fn in_range(key: &str, value: f64, min: f64, max: f64) -> Result<(), ConfigError> {
    if value.is_finite() && (min..=max).contains(&value) {
        Ok(())
    } else {
        Err(ConfigError::new(
            key,
            format!("is {value}, must lie in [{min}, {max}]"),
        ))
    }
}

/// Where byte `offset` of a TOML document is: its 1-based line and the
/// dotted key written on that line (the table header included), if the line
/// holds one. Used to turn parser positions into messages that name the key.
pub fn toml_location(text: &str, offset: usize) -> (Option<usize>, Option<String>) {
    let offset = offset.min(text.len());
    let Some(before) = text.get(..offset) else {
        return (None, None);
    };
    let line_number = before.matches('\n').count() + 1;
    let line = text.lines().nth(line_number - 1).unwrap_or("");
    let trimmed = line.trim();
    if let Some(header) = table_header(trimmed) {
        return (Some(line_number), Some(header));
    }
    let key = trimmed
        .split_once('=')
        .map(|(k, _)| unquote_key(k))
        .filter(|k| !k.is_empty());
    let table = text
        .lines()
        .take(line_number - 1)
        .filter_map(|l| table_header(l.trim()))
        .last();
    let key = match (table, key) {
        (Some(table), Some(key)) => Some(format!("{table}.{key}")),
        (None, Some(key)) => Some(key),
        (_, None) => None,
    };
    (Some(line_number), key)
}

/// `[a.b]` or `[[a.b]]` → `a.b`.
fn table_header(line: &str) -> Option<String> {
    let inner = line.strip_prefix('[')?;
    let inner = inner.strip_prefix('[').unwrap_or(inner);
    let end = inner.find(']')?;
    Some(unquote_key(&inner[..end]))
}

fn unquote_key(key: &str) -> String {
    key.split('.')
        .map(|part| part.trim().trim_matches('"').trim_matches('\''))
        .collect::<Vec<_>>()
        .join(".")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn toml_locations_name_line_and_dotted_key() {
        let text = "# c\n[vehicle]\nwidth_m = 2\n\n[[boulders]]\nradius_m = 1\n";
        assert_eq!(
            toml_location(text, text.find("width").unwrap()),
            (Some(3), Some("vehicle.width_m".into()))
        );
        assert_eq!(
            toml_location(text, text.find("radius").unwrap()),
            (Some(6), Some("boulders.radius_m".into()))
        );
        assert_eq!(toml_location(text, 5), (Some(2), Some("vehicle".into())));
    }

    #[test]
    fn checks_name_the_key_and_the_value() {
        assert_eq!(positive("a", 1.0), Ok(()));
        let err = positive("wheelbase_m", -1.0).unwrap_err().within("vehicle");
        assert_eq!(
            err.to_string(),
            "`vehicle.wheelbase_m`: is -1, must be a finite number > 0"
        );
        assert!(positive("a", f64::NAN).is_err());
        assert!(non_negative("a", 0.0).is_ok());
        assert!(non_negative("a", -0.1).is_err());
        assert!(in_range("a", 0.5, 0.0, 1.0).is_ok());
        assert!(in_range("a", 1.5, 0.0, 1.0).is_err());
    }
}
