//! Session names: every service of one simulation is prefixed with it, so that
//! several simulations (trainees, parallel tests) share a host without meeting.

use thiserror::Error;

/// A validated session name (1-64 characters of `[A-Za-z0-9_-]`).
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct SessionName(String);

/// Why a session name was refused.
#[derive(Debug, Error, PartialEq, Eq)]
pub enum SessionNameError {
    /// The name is empty or longer than 64 characters.
    #[error("session name must have 1 to 64 characters, got {0}")]
    Length(usize),
    /// The name holds a character outside `[A-Za-z0-9_-]`.
    #[error("session name {name:?} holds {ch:?}; use only letters, digits, '-' and '_'")]
    Character {
        /// The refused name.
        name: String,
        /// The first refused character.
        ch: char,
    },
}

impl SessionName {
    /// Validates `name`. Service names end up in file names under `/tmp` and
    /// `/dev/shm`, hence the restricted alphabet.
    pub fn new(name: &str) -> Result<Self, SessionNameError> {
        if name.is_empty() || name.len() > 64 {
            return Err(SessionNameError::Length(name.chars().count()));
        }
        if let Some(ch) = name
            .chars()
            .find(|c| !(c.is_ascii_alphanumeric() || *c == '-' || *c == '_'))
        {
            return Err(SessionNameError::Character {
                name: name.to_owned(),
                ch,
            });
        }
        Ok(Self(name.to_owned()))
    }

    /// The session name as given.
    pub fn as_str(&self) -> &str {
        &self.0
    }

    /// The full service name of `stream` in this session.
    pub fn service(&self, stream: &str) -> String {
        format!("hapsim/{}/{stream}", self.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refuses_bad_names_and_prefixes_good_ones() {
        assert_eq!(SessionName::new(""), Err(SessionNameError::Length(0)));
        assert!(matches!(
            SessionName::new("a/b"),
            Err(SessionNameError::Character { ch: '/', .. })
        ));
        assert!(SessionName::new(&"x".repeat(65)).is_err());
        let s = SessionName::new("lab_2-a").unwrap();
        assert_eq!(s.service("pose"), "hapsim/lab_2-a/pose");
        assert_ne!(
            SessionName::new("a").unwrap().service("pose"),
            SessionName::new("b").unwrap().service("pose")
        );
    }
}
