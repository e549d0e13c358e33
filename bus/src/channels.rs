//! Which channels a subscription or an authentication policy covers: an
//! exact name or a pattern matching whole names, as the reference LCM's
//! subscriptions match them.

/// Which channels a subscription takes.
#[derive(Debug, Clone)]
pub enum ChannelFilter {
    Exact(String),
    /// Anchored: the whole channel name must match, as in the reference.
    Regex(regex::Regex),
}

impl ChannelFilter {
    /// A filter matching channel names that `pattern` matches as a whole
    /// (`ARC_VOTES_.*`), as the reference's subscriptions do.
    pub fn pattern(pattern: &str) -> Result<Self, regex::Error> {
        regex::Regex::new(&format!("^(?:{pattern})$")).map(Self::Regex)
    }

    pub fn matches(&self, channel: &str) -> bool {
        match self {
            Self::Exact(name) => name == channel,
            Self::Regex(re) => re.is_match(channel),
        }
    }
}
