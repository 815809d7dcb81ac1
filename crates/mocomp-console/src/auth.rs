//! Who may do what. Every request that changes anything needs the session's token, sent as
//! `Authorization: Bearer TOKEN` or as the cookie the page gets from its `?token=` link; tokens
//! are compared in constant time. Reading (the page, the status, the WebSocket) needs no token
//! only while the console listens on loopback. Requests must name this console as their `Host`
//! (a page on another site that resolves its name to 127.0.0.1, DNS rebinding, is refused), and
//! a request a browser marks with another `Origin` is refused (no CORS: no other site's page may
//! call this API).

use axum::http::HeaderMap;
use axum::http::header::{AUTHORIZATION, COOKIE, HOST, ORIGIN};
use std::net::SocketAddr;
use subtle::ConstantTimeEq;

/// The cookie that carries the token for the page.
pub const COOKIE_NAME: &str = "mocomp_token";

/// Random bytes in a token (hex-encoded: twice as many characters).
const TOKEN_BYTES: usize = 32;

/// A session's secret.
#[derive(Clone)]
pub struct Token(String);

impl std::fmt::Debug for Token {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // Never in a log.
        f.write_str("Token(..)")
    }
}

impl Token {
    /// A fresh token from the operating system's random source.
    pub fn random() -> Result<Self, getrandom::Error> {
        let mut bytes = [0u8; TOKEN_BYTES];
        getrandom::fill(&mut bytes)?;
        Ok(Self(bytes.iter().map(|b| format!("{b:02x}")).collect()))
    }

    /// The token's text (for the link printed at start, and the token file).
    pub fn as_str(&self) -> &str {
        &self.0
    }

    /// Whether `candidate` is this token, in time that does not depend on where they differ.
    pub fn matches(&self, candidate: &str) -> bool {
        self.0.as_bytes().ct_eq(candidate.as_bytes()).into()
    }

    /// Whether the request carries this token (bearer header or cookie).
    pub fn carried_by(&self, headers: &HeaderMap) -> bool {
        let bearer = headers
            .get_all(AUTHORIZATION)
            .iter()
            .filter_map(|v| v.to_str().ok())
            .filter_map(|v| v.strip_prefix("Bearer "))
            .any(|t| self.matches(t.trim()));
        bearer
            || headers
                .get_all(COOKIE)
                .iter()
                .filter_map(|v| v.to_str().ok())
                .flat_map(cookie::Cookie::split_parse)
                .filter_map(Result::ok)
                .any(|c| c.name() == COOKIE_NAME && self.matches(c.value()))
    }
}

/// The `Set-Cookie` value that gives the page its token: not readable by scripts, sent only to
/// this origin, never with another site's request.
pub fn token_cookie(token: &Token) -> String {
    cookie::Cookie::build((COOKIE_NAME, token.as_str().to_owned()))
        .path("/")
        .http_only(true)
        .same_site(cookie::SameSite::Strict)
        .build()
        .to_string()
}

/// Where the console listens, and what that allows.
#[derive(Debug, Clone, Copy)]
pub struct Site {
    /// The bound address.
    pub addr: SocketAddr,
}

impl Site {
    /// Whether reading needs no token: only on loopback.
    pub fn open_reading(&self) -> bool {
        self.addr.ip().is_loopback()
    }

    /// The names this console answers to (`Host`): its address, and `localhost` on loopback.
    fn is_own_host(&self, host: &str) -> bool {
        let port = self.addr.port();
        let own = self.addr.to_string();
        host == own
            || (self.addr.ip().is_loopback()
                && (host == format!("localhost:{port}") || host == format!("127.0.0.1:{port}")))
    }

    /// Whether the request names this console as its host, and any origin a browser marked it
    /// with is this console's own.
    pub fn same_origin(&self, headers: &HeaderMap) -> bool {
        let Some(host) = headers.get(HOST).and_then(|h| h.to_str().ok()) else {
            return false;
        };
        if !self.is_own_host(host) {
            return false;
        }
        match headers.get(ORIGIN).map(|o| o.to_str()) {
            None => true,
            Some(Ok(origin)) => origin
                .strip_prefix("http://")
                .is_some_and(|o| o == host || self.is_own_host(o)),
            Some(Err(_)) => false,
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;
    use axum::http::HeaderValue;

    fn headers(pairs: &[(axum::http::HeaderName, &str)]) -> HeaderMap {
        let mut h = HeaderMap::new();
        for (k, v) in pairs {
            h.append(k.clone(), HeaderValue::from_str(v).unwrap());
        }
        h
    }

    #[test]
    fn tokens_are_random_and_long() {
        let (a, b) = (Token::random().unwrap(), Token::random().unwrap());
        assert_eq!(a.as_str().len(), 64);
        assert!(a.as_str().bytes().all(|c| c.is_ascii_hexdigit()));
        assert_ne!(a.as_str(), b.as_str());
        assert_eq!(format!("{a:?}"), "Token(..)");
    }

    #[test]
    fn the_token_is_taken_from_the_bearer_header_or_the_cookie_only() {
        let t = Token::random().unwrap();
        let bearer = format!("Bearer {}", t.as_str());
        assert!(t.carried_by(&headers(&[(AUTHORIZATION, &bearer)])));
        let cookie = format!("other=1; {COOKIE_NAME}={}", t.as_str());
        assert!(t.carried_by(&headers(&[(COOKIE, &cookie)])));
        // Wrong, truncated, another scheme, another cookie's name, none.
        let wrong = format!("Bearer {}x", t.as_str());
        assert!(!t.carried_by(&headers(&[(AUTHORIZATION, &wrong)])));
        let short = format!("Bearer {}", &t.as_str()[..63]);
        assert!(!t.carried_by(&headers(&[(AUTHORIZATION, &short)])));
        let basic = format!("Basic {}", t.as_str());
        assert!(!t.carried_by(&headers(&[(AUTHORIZATION, &basic)])));
        let other = format!("token={}", t.as_str());
        assert!(!t.carried_by(&headers(&[(COOKIE, &other)])));
        assert!(!t.carried_by(&HeaderMap::new()));
    }

    #[test]
    fn the_cookie_is_http_only_and_strict() {
        let t = Token::random().unwrap();
        let c = token_cookie(&t);
        assert!(
            c.starts_with(&format!("{COOKIE_NAME}={}", t.as_str())),
            "{c}"
        );
        assert!(c.contains("HttpOnly") && c.contains("SameSite=Strict") && c.contains("Path=/"));
    }

    #[test]
    fn only_this_consoles_host_and_origin_pass() {
        let site = Site {
            addr: "127.0.0.1:8080".parse().unwrap(),
        };
        assert!(site.open_reading());
        assert!(site.same_origin(&headers(&[(HOST, "127.0.0.1:8080")])));
        assert!(site.same_origin(&headers(&[(HOST, "localhost:8080")])));
        assert!(site.same_origin(&headers(&[
            (HOST, "127.0.0.1:8080"),
            (ORIGIN, "http://127.0.0.1:8080")
        ])));
        // Another site's page, a rebound name, another port, no host at all.
        assert!(!site.same_origin(&headers(&[
            (HOST, "127.0.0.1:8080"),
            (ORIGIN, "http://evil.example")
        ])));
        assert!(!site.same_origin(&headers(&[(HOST, "evil.example:8080")])));
        assert!(!site.same_origin(&headers(&[(HOST, "127.0.0.1:8081")])));
        assert!(!site.same_origin(&HeaderMap::new()));
        let remote = Site {
            addr: "10.1.2.3:8080".parse().unwrap(),
        };
        assert!(!remote.open_reading());
        assert!(remote.same_origin(&headers(&[(HOST, "10.1.2.3:8080")])));
        assert!(!remote.same_origin(&headers(&[(HOST, "localhost:8080")])));
    }
}
