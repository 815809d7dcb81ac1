//! Fixed-size ASCII names of the OpenIGTLink header (type: 12 bytes, device: 20 bytes), stored
//! inline so decoding allocates nothing.

use std::fmt;

/// An ASCII name of at most `N` bytes (NUL-padded on the wire; an `N`-byte name has no NUL).
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct Name<const N: usize> {
    bytes: [u8; N],
    len: u8,
}

/// A message type name (12 bytes).
pub type TypeName = Name<12>;
/// A device name (20 bytes).
pub type DeviceName = Name<20>;

/// A name that does not fit or is not printable ASCII.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("name {name:?}: {reason}")]
pub struct NameError {
    /// The name given.
    pub name: String,
    /// What is wrong.
    pub reason: String,
}

impl<const N: usize> Name<N> {
    /// The empty name.
    pub const fn empty() -> Self {
        Self {
            bytes: [0u8; N],
            len: 0,
        }
    }

    /// A name from text: printable ASCII, at most `N` bytes.
    pub fn new(s: &str) -> Result<Self, NameError> {
        if s.len() > N {
            return Err(NameError {
                name: s.to_string(),
                reason: format!("{} bytes, at most {N} fit", s.len()),
            });
        }
        if let Some(c) = s.chars().find(|c| !(c.is_ascii_graphic() || *c == ' ')) {
            return Err(NameError {
                name: s.to_string(),
                reason: format!("{c:?} is not printable ASCII"),
            });
        }
        let mut bytes = [0u8; N];
        bytes[..s.len()].copy_from_slice(s.as_bytes());
        Ok(Self {
            bytes,
            len: s.len() as u8,
        })
    }

    /// A name from its wire bytes (up to the first NUL). `None` when the bytes are not ASCII.
    pub fn from_wire(raw: &[u8; N]) -> Option<Self> {
        let len = raw.iter().position(|&b| b == 0).unwrap_or(N);
        if !raw[..len].is_ascii() {
            return None;
        }
        let mut bytes = [0u8; N];
        bytes[..len].copy_from_slice(&raw[..len]);
        Some(Self {
            bytes,
            len: len as u8,
        })
    }

    /// The wire bytes (NUL-padded).
    pub fn wire(&self) -> &[u8; N] {
        &self.bytes
    }

    /// The name.
    pub fn as_str(&self) -> &str {
        // Only ASCII is ever stored.
        std::str::from_utf8(&self.bytes[..usize::from(self.len)]).unwrap_or("")
    }
}

impl<const N: usize> fmt::Debug for Name<N> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:?}", self.as_str())
    }
}

impl<const N: usize> fmt::Display for Name<N> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl<const N: usize> PartialEq<str> for Name<N> {
    fn eq(&self, other: &str) -> bool {
        self.as_str() == other
    }
}

impl<const N: usize> PartialEq<&str> for Name<N> {
    fn eq(&self, other: &&str) -> bool {
        self.as_str() == *other
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_are_checked() {
        let n = DeviceName::new("HeadToTracker").unwrap();
        assert_eq!(n, "HeadToTracker");
        assert_eq!(DeviceName::from_wire(n.wire()).unwrap(), n);
        let full = TypeName::new("GET_TRANSFOR").unwrap();
        assert_eq!(full.wire(), b"GET_TRANSFOR", "12 bytes, no NUL");
        assert!(
            TypeName::new("GET_TRANSFORM")
                .unwrap_err()
                .to_string()
                .contains("13 bytes")
        );
        assert!(DeviceName::new("Kopf→Tracker").is_err());
        assert!(DeviceName::from_wire(&[0xC3; 20]).is_none());
    }
}
