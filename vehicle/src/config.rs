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

#[cfg(test)]
mod tests {
    use super::*;

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
