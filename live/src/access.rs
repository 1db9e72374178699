//! Who may use the live view's surfaces (the operator page and the Foxglove WebSocket): the
//! `Host` a request names and the `Origin` a browser names must be on an allow-list, and the page's
//! commands carry a per-session token that only the served page knows.
//!
//! A page of another site cannot read this server's answers (no CORS is granted), but with DNS
//! rebinding its own name resolves to this server, so it sends `Host: evil.example` and
//! `Origin: http://evil.example`: comparing Origin with Host passes it. Checking both against names
//! the operator chose (loopback by default: `localhost`, `127.0.0.1`, `[::1]`, with the server's
//! port) refuses it, and the token, embedded in the page this server serves, refuses a command from
//! anything that did not load that page.

use std::fmt;

/// The header that carries the page's token on a command.
pub const TOKEN_HEADER: &str = "x-operator-token";

/// Host names every server allows (loopback).
pub const LOOPBACK: [&str; 3] = ["localhost", "127.0.0.1", "::1"];

/// The allow-list of host names (without port) and of extra origins for the WebSocket.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Access {
    /// Lowercase host names, IPv6 without brackets.
    hosts: Vec<String>,
    /// Exact origins (`https://app.foxglove.dev`) the WebSocket also accepts (read only).
    origins: Vec<String>,
}

impl Access {
    /// Loopback, the address the server binds (unless it is a wildcard) and `extra_hosts`; the
    /// WebSocket also accepts `extra_origins`.
    #[must_use]
    pub fn new(bind_host: &str, extra_hosts: &[String], extra_origins: &[String]) -> Self {
        let mut hosts: Vec<String> = LOOPBACK.iter().map(|h| (*h).to_owned()).collect();
        let wildcard = matches!(bind_host, "0.0.0.0" | "::" | "[::]");
        let bind = (!wildcard).then_some(bind_host);
        for h in bind
            .into_iter()
            .chain(extra_hosts.iter().map(String::as_str))
        {
            let h = h
                .trim()
                .trim_start_matches('[')
                .trim_end_matches(']')
                .to_ascii_lowercase();
            if !h.is_empty() && !hosts.contains(&h) {
                hosts.push(h);
            }
        }
        let origins = extra_origins
            .iter()
            .map(|o| o.trim().trim_end_matches('/').to_ascii_lowercase())
            .collect();
        Self { hosts, origins }
    }

    /// Loopback only.
    #[must_use]
    pub fn loopback() -> Self {
        Self::new("127.0.0.1", &[], &[])
    }

    /// Whether `host` (a `Host` header: `name`, `name:port`, `[v6]:port`) names an allowed host
    /// and `port` (the server's; 80 when the header names none).
    #[must_use]
    pub fn host_ok(&self, host: &str, port: u16) -> bool {
        split_host(host)
            .is_some_and(|(name, p)| p.unwrap_or(80) == port && self.hosts.contains(&name))
    }

    /// Whether `origin` (an `Origin` header) is `http://` an allowed host and `port`, or, with
    /// `extra`, one of the extra origins.
    #[must_use]
    pub fn origin_ok(&self, origin: &str, port: u16, extra: bool) -> bool {
        let origin = origin.trim().to_ascii_lowercase();
        if extra && self.origins.contains(&origin) {
            return true;
        }
        origin
            .strip_prefix("http://")
            .is_some_and(|rest| self.host_ok(rest, port))
    }

    /// Checks a request's `Host` (required) and `Origin` (when the client names one) for the
    /// server on `port`; `extra` also accepts the extra origins.
    ///
    /// # Errors
    /// Why the request is refused.
    pub fn check(
        &self,
        host: Option<&str>,
        origin: Option<&str>,
        port: u16,
        extra: bool,
    ) -> Result<(), String> {
        match host {
            Some(h) if self.host_ok(h, port) => {}
            Some(h) => return Err(format!("Host {h:?} is not on the allow-list ({self})")),
            None => return Err("a request names its Host".to_owned()),
        }
        match origin {
            Some(o) if !self.origin_ok(o, port, extra) => {
                Err(format!("Origin {o:?} is not on the allow-list ({self})"))
            }
            _ => Ok(()),
        }
    }
}

impl fmt::Display for Access {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let names: Vec<String> = self
            .hosts
            .iter()
            .map(|h| {
                if h.contains(':') {
                    format!("[{h}]")
                } else {
                    h.clone()
                }
            })
            .collect();
        write!(f, "{}", names.join(", "))
    }
}

/// A `Host` value's lowercase name (IPv6 without brackets) and port, if it is well formed.
fn split_host(host: &str) -> Option<(String, Option<u16>)> {
    let host = host.trim();
    let (name, port) = if let Some(rest) = host.strip_prefix('[') {
        let (name, after) = rest.split_once(']')?;
        let port = match after {
            "" => None,
            p => Some(p.strip_prefix(':')?),
        };
        (name, port)
    } else {
        match host.split_once(':') {
            Some((name, p)) => (name, Some(p)),
            None => (host, None),
        }
    };
    if name.is_empty() {
        return None;
    }
    let port = match port {
        Some(p) => Some(p.parse::<u16>().ok()?),
        None => None,
    };
    Some((name.to_ascii_lowercase(), port))
}

/// The page's per-session command token: 128 bits from the OS random source, as 32 hex digits.
#[derive(Clone, PartialEq, Eq)]
pub struct Token(String);

impl Token {
    /// A fresh token.
    ///
    /// # Errors
    /// The OS random source cannot be read.
    pub fn random() -> std::io::Result<Self> {
        let mut bytes = [0_u8; 16];
        getrandom::fill(&mut bytes).map_err(|e| std::io::Error::other(e.to_string()))?;
        Ok(Self(bytes.iter().map(|b| format!("{b:02x}")).collect()))
    }

    /// The token's text (for the page).
    #[must_use]
    pub fn as_str(&self) -> &str {
        &self.0
    }

    /// Whether `given` is this token, in time that does not depend on where they differ.
    #[must_use]
    pub fn matches(&self, given: &[u8]) -> bool {
        let mine = self.0.as_bytes();
        if given.len() != mine.len() {
            return false;
        }
        mine.iter()
            .zip(given)
            .fold(0_u8, |acc, (a, b)| acc | (a ^ b))
            == 0
    }
}

impl fmt::Debug for Token {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        // Never in a log.
        f.write_str("Token(..)")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const PORT: u16 = 8766;

    #[test]
    fn loopback_names_with_the_port_pass_and_rebinding_names_do_not() {
        let a = Access::loopback();
        for ok in [
            "localhost:8766",
            "127.0.0.1:8766",
            "[::1]:8766",
            "LOCALHOST:8766",
        ] {
            assert!(a.host_ok(ok, PORT), "{ok}");
        }
        for bad in [
            "evil.example:8766",
            "evil.example",
            "localhost:8767",
            "localhost",
            "127.0.0.1.evil.example:8766",
            "[::1",
            ":8766",
            "localhost:x",
        ] {
            assert!(!a.host_ok(bad, PORT), "{bad}");
        }
        assert!(a.origin_ok("http://localhost:8766", PORT, false));
        for bad in [
            "http://evil.example:8766",
            "null",
            "https://localhost:8766",
            "http://localhost:9",
        ] {
            assert!(!a.origin_ok(bad, PORT, true), "{bad}");
        }
        // Host = Origin = the rebinding name: refused.
        let e = a
            .check(
                Some("evil.example:8766"),
                Some("http://evil.example:8766"),
                PORT,
                false,
            )
            .unwrap_err();
        assert!(e.contains("evil.example"), "{e}");
        assert!(a.check(None, None, PORT, false).is_err());
    }

    #[test]
    fn configured_hosts_and_origins_are_allowed() {
        let a = Access::new(
            "0.0.0.0",
            &["Excavator.local".into()],
            &["https://app.foxglove.dev/".into()],
        );
        assert!(a.host_ok("excavator.local:8766", PORT));
        assert!(!a.host_ok("0.0.0.0:8766", PORT));
        assert!(a.origin_ok("https://app.foxglove.dev", PORT, true));
        assert!(!a.origin_ok("https://app.foxglove.dev", PORT, false));
        let bound = Access::new("192.168.1.5", &[], &[]);
        assert!(bound.host_ok("192.168.1.5:8766", PORT));
    }

    #[test]
    fn the_token_is_random_and_compared_whole() {
        let t = Token::random().unwrap();
        let u = Token::random().unwrap();
        assert_ne!(t, u);
        assert_eq!(t.as_str().len(), 32);
        assert!(t.matches(t.as_str().as_bytes()));
        assert!(!t.matches(u.as_str().as_bytes()));
        assert!(!t.matches(&t.as_str().as_bytes()[..31]));
        assert!(!t.matches(b""));
        assert_eq!(format!("{t:?}"), "Token(..)");
    }
}
