//! LCM provider URLs: `udpm://GROUP:PORT?ttl=N&recv_buf_size=B&transmit_only=BOOL`
//! and `memq://`.

use std::net::Ipv4Addr;
use std::str::FromStr;

/// The reference implementation's default provider.
pub const DEFAULT_URL: &str = "udpm://239.255.76.67:7667?ttl=0";

const DEFAULT_GROUP: Ipv4Addr = Ipv4Addr::new(239, 255, 76, 67);
const DEFAULT_PORT: u16 = 7667;

/// A parsed provider URL.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LcmUrl {
    Udpm(UdpmUrl),
    /// In-process queue: only this `Lcm` instance receives what it publishes.
    Memq,
}

impl LcmUrl {
    /// Whether `self` and `other` are one bus, however spelt: the same
    /// multicast group and port (TTL, buffer size and transmit-only are how
    /// a process uses a bus, not which bus it is). Two `memq://` instances
    /// are two queues, never one bus.
    pub fn same_bus(&self, other: &LcmUrl) -> bool {
        match (self, other) {
            (LcmUrl::Udpm(a), LcmUrl::Udpm(b)) => a.group == b.group && a.port == b.port,
            _ => false,
        }
    }
}

/// UDP multicast settings.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct UdpmUrl {
    pub group: Ipv4Addr,
    pub port: u16,
    /// Multicast TTL; 0 keeps traffic on this host.
    pub ttl: u8,
    /// Socket receive buffer to ask the kernel for, bytes.
    pub recv_buf_size: Option<usize>,
    /// Publish only: no receive socket.
    pub transmit_only: bool,
}

impl Default for UdpmUrl {
    fn default() -> Self {
        Self {
            group: DEFAULT_GROUP,
            port: DEFAULT_PORT,
            ttl: 0,
            recv_buf_size: None,
            transmit_only: false,
        }
    }
}

/// A provider URL that cannot be used.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("LCM URL {url:?}: {reason}")]
pub struct UrlError {
    pub url: String,
    pub reason: String,
}

impl FromStr for LcmUrl {
    type Err = UrlError;

    fn from_str(url: &str) -> Result<Self, UrlError> {
        let fail = |reason: String| UrlError {
            url: url.to_owned(),
            reason,
        };
        if url.is_empty() {
            return DEFAULT_URL.parse();
        }
        let (scheme, rest) = url.split_once("://").ok_or_else(|| {
            fail("expected PROVIDER://..., e.g. udpm://239.255.76.67:7667?ttl=0 or memq://".into())
        })?;
        let (address, query) = rest.split_once('?').unwrap_or((rest, ""));
        match scheme {
            "memq" => {
                if !address.is_empty() || !query.is_empty() {
                    return Err(fail("memq:// takes no address or options".into()));
                }
                Ok(LcmUrl::Memq)
            }
            "udpm" => {
                let mut settings = UdpmUrl::default();
                if !address.is_empty() {
                    let (group, port) = address
                        .rsplit_once(':')
                        .ok_or_else(|| fail(format!("address {address:?} must be GROUP:PORT")))?;
                    settings.group = group
                        .parse()
                        .map_err(|_| fail(format!("{group:?} is not an IPv4 address")))?;
                    if !settings.group.is_multicast() {
                        return Err(fail(format!(
                            "{group} is not a multicast address (224.0.0.0 to 239.255.255.255)"
                        )));
                    }
                    settings.port = port
                        .parse()
                        .ok()
                        .filter(|&p| p > 0)
                        .ok_or_else(|| fail(format!("{port:?} is not a port (1 to 65535)")))?;
                }
                for option in query.split('&').filter(|o| !o.is_empty()) {
                    let (key, value) = option
                        .split_once('=')
                        .ok_or_else(|| fail(format!("option {option:?} must be KEY=VALUE")))?;
                    match key {
                        "ttl" => {
                            settings.ttl = value
                                .parse()
                                .map_err(|_| fail(format!("ttl={value:?} must be 0 to 255")))?;
                        }
                        "recv_buf_size" => {
                            settings.recv_buf_size =
                                Some(value.parse().ok().filter(|&n| n > 0).ok_or_else(|| {
                                    fail(format!(
                                        "recv_buf_size={value:?} must be a positive number of bytes"
                                    ))
                                })?);
                        }
                        "transmit_only" => {
                            settings.transmit_only = match value {
                                "true" | "1" => true,
                                "false" | "0" => false,
                                _ => {
                                    return Err(fail(format!(
                                        "transmit_only={value:?} must be true or false"
                                    )));
                                }
                            };
                        }
                        _ => {
                            return Err(fail(format!(
                                "unknown option {key:?} (known: ttl, recv_buf_size, transmit_only)"
                            )));
                        }
                    }
                }
                Ok(LcmUrl::Udpm(settings))
            }
            other => Err(fail(format!(
                "unknown provider {other:?} (known: udpm, memq)"
            ))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_url_is_the_references() {
        let LcmUrl::Udpm(u) = "".parse().unwrap() else {
            panic!("udpm expected")
        };
        assert_eq!(u, UdpmUrl::default());
        assert_eq!(u.group, Ipv4Addr::new(239, 255, 76, 67));
        assert_eq!((u.port, u.ttl), (7667, 0));
        assert_eq!(
            DEFAULT_URL.parse::<LcmUrl>().unwrap(),
            LcmUrl::Udpm(UdpmUrl::default())
        );
    }

    #[test]
    fn options_are_parsed() {
        let LcmUrl::Udpm(u) =
            "udpm://239.1.2.3:1234?ttl=1&recv_buf_size=4000000&transmit_only=true"
                .parse()
                .unwrap()
        else {
            panic!("udpm expected")
        };
        assert_eq!(u.group, Ipv4Addr::new(239, 1, 2, 3));
        assert_eq!(
            (u.port, u.ttl, u.recv_buf_size, u.transmit_only),
            (1234, 1, Some(4_000_000), true)
        );
        assert_eq!("memq://".parse::<LcmUrl>().unwrap(), LcmUrl::Memq);
    }

    #[test]
    fn bad_urls_say_what_is_wrong() {
        let reason = |url: &str| url.parse::<LcmUrl>().unwrap_err().reason;
        assert!(reason("tcp://1.2.3.4:5").contains("unknown provider \"tcp\""));
        assert!(reason("udpm://10.0.0.1:7667").contains("not a multicast address"));
        assert!(reason("udpm://239.0.0.1:99999").contains("is not a port"));
        assert!(reason("udpm://239.0.0.1").contains("GROUP:PORT"));
        assert!(reason("udpm://239.0.0.1:7667?ttl=300").contains("ttl"));
        assert!(reason("udpm://239.0.0.1:7667?color=red").contains("unknown option \"color\""));
        assert!(reason("239.0.0.1:7667").contains("PROVIDER://"));
        assert!(reason("memq://x").contains("no address"));
    }
}
