//! `[bus]`: how arcnav's processes trust each other on LCM.

use std::path::{Path, PathBuf};

use arcnav_bus::auth::{AuthPolicy, Freshness, GroupKey, KeyError};
use arcnav_vehicle::ConfigError;
use arcnav_vehicle::config;
use serde::{Deserialize, Serialize};

/// Lives in `[bus]`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BusConfig {
    pub auth: BusAuthConfig,
}

impl BusConfig {
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.auth.validate().map_err(|e| e.within("auth"))
    }
}

/// Lives in `[bus.auth]`: authenticated messages (see `arcnav_bus::auth`).
/// Off unless `key_file` names a key.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BusAuthConfig {
    /// The group key: a file of hex digits (at least 32 bytes), readable by
    /// its owner only; relative to the configuration file's directory.
    /// Empty: authentication off.
    pub key_file: PathBuf,
    /// Channels signed on publication and verified on receipt, as patterns
    /// matching whole channel names.
    pub channels: Vec<String>,
    /// A message older than this by the receiver's clock is refused, s.
    pub max_age_s: f64,
    /// A message stamped further ahead of the receiver's clock is refused, s.
    pub max_skew_s: f64,
    /// A message further behind the newest accepted on its channel is
    /// refused as replayed (one already accepted always is), s.
    pub window_s: f64,
}

impl Default for BusAuthConfig {
    fn default() -> Self {
        let freshness = Freshness::default();
        Self {
            key_file: PathBuf::new(),
            channels: ["STEERING_COMMAND", "ARC_VOTES_.*", "WAYPOINTS"]
                .map(str::to_owned)
                .to_vec(),
            max_age_s: freshness.max_age_us as f64 / 1e6,
            max_skew_s: freshness.max_skew_us as f64 / 1e6,
            window_s: freshness.window_us as f64 / 1e6,
        }
    }
}

impl BusAuthConfig {
    /// Keys relative to `[bus.auth]`.
    pub fn validate(&self) -> Result<(), ConfigError> {
        config::in_range("max_age_s", self.max_age_s, 0.001, 3600.0)?;
        config::in_range("max_skew_s", self.max_skew_s, 0.0, 3600.0)?;
        config::in_range("window_s", self.window_s, 0.0, 3600.0)?;
        if self.enabled() && self.channels.is_empty() {
            return Err(ConfigError::new(
                "channels",
                "is empty: name the channels to authenticate (e.g. \"STEERING_COMMAND\")",
            ));
        }
        for pattern in &self.channels {
            if let Some(e) = AuthPolicy::pattern_error(pattern) {
                return Err(ConfigError::new(
                    "channels",
                    format!("{pattern:?} is not a pattern: {e}"),
                ));
            }
        }
        Ok(())
    }

    /// True when a key file is named.
    pub fn enabled(&self) -> bool {
        !self.key_file.as_os_str().is_empty()
    }

    /// The key file, relative paths taken from `base` (the configuration
    /// file's directory).
    pub fn key_path(&self, base: &Path) -> PathBuf {
        base.join(&self.key_file)
    }

    /// The policy to give the transport, reading the key; `None` when off.
    pub fn policy(&self, base: &Path) -> Result<Option<AuthPolicy>, KeyError> {
        if !self.enabled() {
            return Ok(None);
        }
        let path = self.key_path(base);
        let key = GroupKey::from_file(&path)?;
        let micros = |s: f64| (s * 1e6).round() as u64;
        let freshness = Freshness {
            max_age_us: micros(self.max_age_s),
            max_skew_us: micros(self.max_skew_s),
            window_us: micros(self.window_s),
        };
        AuthPolicy::new(key, freshness, &self.channels)
            .map(Some)
            .map_err(|e| KeyError::Malformed {
                path,
                reason: format!("the channel patterns of [bus.auth]: {e}"),
            })
    }
}
