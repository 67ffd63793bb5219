//! ROS 2 names as they appear on the DDS wire (the rmw layer's mangling): a
//! topic `/MTMR/measured_cp` is the DDS topic `rt/MTMR/measured_cp`, a
//! message type `geometry_msgs/msg/PoseStamped` the DDS type
//! `geometry_msgs::msg::dds_::PoseStamped_`. Pure: no I/O.

use std::fmt;

/// A name that is not a ROS 2 topic or message type name.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum NameError {
    /// Not a topic name; the reason, and what would be accepted.
    #[error("topic `{name}`: {why} (a ROS 2 topic name is tokens of letters, digits and `_`, none starting with a digit, separated by `/`, e.g. `/MTMR/measured_cp`)")]
    Topic {
        /// The name given.
        name: String,
        /// What is wrong with it.
        why: &'static str,
    },
    /// Not a message type name.
    #[error("message type `{0}`: expected `package/msg/Type` (e.g. `geometry_msgs/msg/PoseStamped`), `package/Type`, or the DDS form `package::msg::dds_::Type_`")]
    Type(String),
}

/// A fully qualified ROS 2 topic name (`/a/b`). A relative name (`a/b`)
/// is taken relative to the root namespace, as a node in `/` would.
#[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct TopicName(String);

impl TopicName {
    /// Checks `text` as a ROS 2 topic name.
    pub fn parse(text: &str) -> Result<TopicName, NameError> {
        let bad = |why| NameError::Topic { name: text.to_string(), why };
        let body = text.strip_prefix('/').unwrap_or(text);
        if body.is_empty() {
            return Err(bad("empty"));
        }
        if body.ends_with('/') {
            return Err(bad("ends with `/`"));
        }
        for token in body.split('/') {
            let mut chars = token.chars();
            match chars.next() {
                None => return Err(bad("has an empty token (`//`)")),
                Some(c) if c.is_ascii_digit() => return Err(bad("has a token starting with a digit")),
                Some(_) => {}
            }
            if !token.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
                return Err(bad("has a character other than a letter, digit, `_` or `/`"));
            }
        }
        Ok(TopicName(format!("/{body}")))
    }

    /// The ROS 2 name, `/a/b`.
    pub fn as_str(&self) -> &str {
        &self.0
    }

    /// The DDS topic of ROS 2 messages on it: `rt/a/b`.
    pub fn dds(&self) -> String {
        format!("rt{}", self.0)
    }

    /// The ROS 2 topic whose messages travel on the DDS topic `dds`, if it
    /// is one (`rt/…`).
    pub fn from_dds(dds: &str) -> Option<TopicName> {
        dds.strip_prefix("rt/").and_then(|n| TopicName::parse(n).ok())
    }
}

impl fmt::Display for TopicName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::str::FromStr for TopicName {
    type Err = NameError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        TopicName::parse(s)
    }
}

/// A ROS 2 message type: package, interface kind (`msg`) and name.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct TypeName {
    package: String,
    name: String,
}

/// Whether `s` is an identifier of the ROS 2 interface names: a letter,
/// then letters, digits and `_`.
fn identifier(s: &str) -> bool {
    s.chars().next().is_some_and(|c| c.is_ascii_alphabetic()) && s.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
}

impl TypeName {
    /// Reads `pkg/msg/Type`, `pkg/Type` or the DDS form
    /// `pkg::msg::dds_::Type_`.
    pub fn parse(text: &str) -> Result<TypeName, NameError> {
        let bad = || NameError::Type(text.to_string());
        let (package, name) = if let Some(rest) = text.strip_suffix('_').filter(|_| text.contains("::")) {
            let parts: Vec<&str> = rest.split("::").collect();
            match parts[..] {
                [p, "msg", "dds_", n] => (p, n),
                _ => return Err(bad()),
            }
        } else {
            let parts: Vec<&str> = text.split('/').collect();
            match parts[..] {
                [p, "msg", n] | [p, n] => (p, n),
                _ => return Err(bad()),
            }
        };
        if !identifier(package) || !identifier(name) {
            return Err(bad());
        }
        Ok(TypeName { package: package.to_string(), name: name.to_string() })
    }

    /// The ROS 2 name, `pkg/msg/Type`.
    pub fn ros(&self) -> String {
        format!("{}/msg/{}", self.package, self.name)
    }

    /// The DDS type name, `pkg::msg::dds_::Type_`.
    pub fn dds(&self) -> String {
        format!("{}::msg::dds_::{}_", self.package, self.name)
    }
}

impl fmt::Display for TypeName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/msg/{}", self.package, self.name)
    }
}

impl std::str::FromStr for TypeName {
    type Err = NameError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        TypeName::parse(s)
    }
}

/// The type hash a ROS 2 endpoint announces in its DDS user data
/// (`typehash=RIHS01_…;`, from ROS 2 Iron on), if any.
/// The user data comes as its parameter's value, a CDR sequence (a 4-byte
/// length, the text, padding), so the key is looked for where it begins
/// after that or after a `;`.
pub fn type_hash(user_data: &[u8]) -> Option<String> {
    const KEY: &[u8] = b"typehash=";
    let at = (0..user_data.len()).find(|&i| user_data[i..].starts_with(KEY) && (i == 0 || i == 4 || user_data[i - 1] == b';'))? + KEY.len();
    let rest = &user_data[at..];
    let hash = &rest[..rest.iter().position(|&b| b == b';' || b == 0).unwrap_or(rest.len())];
    std::str::from_utf8(hash).ok().filter(|h| !h.is_empty()).map(str::to_string)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn topics_are_mangled_as_the_rmw_does_and_bad_names_say_why() {
        let t = TopicName::parse("/MTMR/measured_cp").unwrap();
        assert_eq!((t.as_str(), t.dds().as_str()), ("/MTMR/measured_cp", "rt/MTMR/measured_cp"));
        assert_eq!(TopicName::parse("chatter").unwrap().dds(), "rt/chatter");
        assert_eq!(TopicName::from_dds("rt/PSM1/servo_cp"), Some(TopicName::parse("/PSM1/servo_cp").unwrap()));
        assert_eq!(TopicName::from_dds("ros_discovery_info"), None);
        for (bad, why) in [("", "empty"), ("/", "empty"), ("/a//b", "empty token"), ("/a/", "ends with"), ("/1a", "digit"), ("/a-b", "character")] {
            let e = TopicName::parse(bad).unwrap_err().to_string();
            assert!(e.contains(why), "{bad}: {e}");
        }
    }

    #[test]
    fn types_read_in_every_form_and_write_as_ros_and_dds() {
        for text in ["geometry_msgs/msg/PoseStamped", "geometry_msgs/PoseStamped", "geometry_msgs::msg::dds_::PoseStamped_"] {
            let t = TypeName::parse(text).unwrap();
            assert_eq!(t.ros(), "geometry_msgs/msg/PoseStamped");
            assert_eq!(t.dds(), "geometry_msgs::msg::dds_::PoseStamped_");
        }
        for bad in ["", "PoseStamped", "a/srv/b/c", "geometry_msgs::msg::PoseStamped_", "1pkg/msg/T", "pkg/msg/T-x"] {
            assert!(TypeName::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn the_type_hash_is_read_from_the_user_data() {
        assert_eq!(type_hash(b"typehash=RIHS01_abc;"), Some("RIHS01_abc".to_string()));
        assert_eq!(type_hash(b"enclave=/;typehash=RIHS01_x;"), Some("RIHS01_x".to_string()));
        assert_eq!(type_hash(b""), None);
        assert_eq!(type_hash(&[0xff, 0xfe]), None);
        // As the parameter carries it: a CDR sequence's length, the text,
        // then padding.
        let mut cdr = vec![0x95, 0, 0, 0];
        cdr.extend_from_slice(b"typehash=RIHS01_5f2d;\0\0\0");
        assert_eq!(type_hash(&cdr), Some("RIHS01_5f2d".to_string()));
        assert_eq!(type_hash(b"xtypehash=RIHS01_no;"), None);
    }
}
