//! The `--via` URL: which transport, to where.

use std::fmt;
use std::str::FromStr;

/// socketcand's registered port, used when a `socketcand://` URL names none.
pub const DEFAULT_SOCKETCAND_PORT: u16 = 29536;

/// The longest Linux interface name (IFNAMSIZ less the NUL).
const MAX_INTERFACE_LEN: usize = 15;

/// Where the bus is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Via {
    /// `socketcand://HOST[:PORT]/BUS`: a socketcand server (the virtual car's, or a daemon
    /// next to a real bus), raw mode.
    Socketcand {
        /// Host name or address (an IPv6 address without its brackets).
        host: String,
        /// TCP port ([`DEFAULT_SOCKETCAND_PORT`] when the URL gives none).
        port: u16,
        /// The bus the server is asked to open, e.g. `can0`.
        bus: String,
    },
    /// `socketcan://IFACE`: a Linux SocketCAN interface, e.g. a USB-CAN adapter's `can0`.
    Socketcan {
        /// The interface name.
        interface: String,
    },
}

/// A `--via` URL that is not one.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ViaError {
    /// The URL as given.
    pub url: String,
    /// What is wrong with it.
    pub reason: String,
}

impl fmt::Display for ViaError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "invalid transport URL '{}': {} (expected socketcand://HOST:PORT/BUS or socketcan://IFACE)",
            self.url, self.reason
        )
    }
}

impl std::error::Error for ViaError {}

impl FromStr for Via {
    type Err = ViaError;

    fn from_str(url: &str) -> Result<Self, ViaError> {
        let error = |reason: String| ViaError {
            url: url.to_string(),
            reason,
        };
        let Some((scheme, rest)) = url.split_once("://") else {
            return Err(error("no scheme (the part before '://')".into()));
        };
        match scheme.to_ascii_lowercase().as_str() {
            "socketcand" => parse_socketcand(rest).map_err(error),
            "socketcan" => {
                let interface = rest.strip_suffix('/').unwrap_or(rest);
                if interface.is_empty() {
                    return Err(error("no interface name after 'socketcan://'".into()));
                }
                if interface.len() > MAX_INTERFACE_LEN
                    || !interface
                        .chars()
                        .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'))
                {
                    return Err(error(format!(
                        "'{interface}' is not a network interface name (letters, digits, '-', '_', '.'; at most {MAX_INTERFACE_LEN})"
                    )));
                }
                Ok(Via::Socketcan {
                    interface: interface.to_string(),
                })
            }
            "virtual" => Err(error(
                "the in-process virtual car transport is not available yet; run the virtual car with --socketcand HOST:PORT and use socketcand://HOST:PORT/can0".into(),
            )),
            other => Err(error(format!("unknown transport '{other}'"))),
        }
    }
}

fn parse_socketcand(rest: &str) -> Result<Via, String> {
    let Some((authority, bus)) = rest.split_once('/') else {
        return Err("no bus: add '/can0' (or the bus the server has) after the port".into());
    };
    if bus.is_empty() {
        return Err("empty bus name after the '/'".into());
    }
    if !bus
        .chars()
        .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'))
    {
        return Err(format!(
            "'{bus}' is not a bus name (letters, digits, '-', '_', '.')"
        ));
    }
    let (host, port) = if let Some(bracketed) = authority.strip_prefix('[') {
        let (host, after) = bracketed
            .split_once(']')
            .ok_or("an IPv6 address without its closing ']'")?;
        let port = match after {
            "" => None,
            _ => Some(
                after
                    .strip_prefix(':')
                    .ok_or_else(|| format!("unexpected '{after}' after the IPv6 address"))?,
            ),
        };
        (host, port)
    } else {
        match authority.rsplit_once(':') {
            Some((host, port)) => (host, Some(port)),
            None => (authority, None),
        }
    };
    if host.is_empty() {
        return Err("no host".into());
    }
    let port = match port {
        None => DEFAULT_SOCKETCAND_PORT,
        Some(text) => match text.parse::<u16>() {
            Ok(0) | Err(_) => return Err(format!("port '{text}' is not a number in 1..=65535")),
            Ok(port) => port,
        },
    };
    Ok(Via::Socketcand {
        host: host.to_string(),
        port,
        bus: bus.to_string(),
    })
}

impl fmt::Display for Via {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Via::Socketcand { host, port, bus } if host.contains(':') => {
                write!(f, "socketcand://[{host}]:{port}/{bus}")
            }
            Via::Socketcand { host, port, bus } => write!(f, "socketcand://{host}:{port}/{bus}"),
            Via::Socketcan { interface } => write!(f, "socketcan://{interface}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn socketcand(host: &str, port: u16, bus: &str) -> Via {
        Via::Socketcand {
            host: host.into(),
            port,
            bus: bus.into(),
        }
    }

    #[test]
    fn good_urls() {
        assert_eq!(
            "socketcand://127.0.0.1:29536/can0".parse(),
            Ok(socketcand("127.0.0.1", 29536, "can0"))
        );
        assert_eq!(
            "socketcand://bench.local/vcan1".parse(),
            Ok(socketcand("bench.local", DEFAULT_SOCKETCAND_PORT, "vcan1"))
        );
        assert_eq!(
            "socketcand://[::1]:4000/can0".parse(),
            Ok(socketcand("::1", 4000, "can0"))
        );
        assert_eq!(
            "socketcan://can0".parse(),
            Ok(Via::Socketcan {
                interface: "can0".into()
            })
        );
        for url in [
            "socketcand://127.0.0.1:29536/can0",
            "socketcand://[::1]:4000/can0",
            "socketcan://can0",
        ] {
            assert_eq!(url.parse::<Via>().unwrap().to_string(), url);
        }
    }

    #[test]
    fn bad_urls_say_what_is_wrong() {
        let reason = |url: &str| url.parse::<Via>().unwrap_err().to_string();
        assert!(reason("127.0.0.1:29536").contains("no scheme"));
        assert!(reason("tcp://127.0.0.1:29536/can0").contains("unknown transport 'tcp'"));
        assert!(reason("socketcand://127.0.0.1:29536").contains("no bus"));
        assert!(reason("socketcand://127.0.0.1:29536/").contains("empty bus name"));
        assert!(reason("socketcand://127.0.0.1:port/can0").contains("port 'port'"));
        assert!(reason("socketcand://127.0.0.1:0/can0").contains("port '0'"));
        assert!(reason("socketcand://127.0.0.1:70000/can0").contains("port '70000'"));
        assert!(reason("socketcand://:29536/can0").contains("no host"));
        assert!(reason("socketcand://[::1/can0").contains("closing ']'"));
        assert!(reason("socketcan://").contains("no interface"));
        assert!(reason("socketcan://can0/x").contains("not a network interface"));
        assert!(reason("virtual://").contains("not available yet"));
        // Every message shows the URL and the accepted forms.
        let text = reason("tcp://x");
        assert!(text.contains("'tcp://x'"), "{text}");
        assert!(text.contains("socketcand://HOST:PORT/BUS"), "{text}");
    }
}
