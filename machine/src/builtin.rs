//! The machine profiles shipped with Lamina (`machine/profiles/`, inside the crate so
//! that it packages), embedded so that a pipeline names them without knowing where
//! Lamina is installed.

/// A shipped profile: the name a pipeline uses and the profile's text.
#[derive(Debug, Clone, Copy)]
pub struct BuiltinProfile {
    pub name: &'static str,
    /// Where the text lives in the repository, for messages.
    pub path: &'static str,
    pub text: &'static str,
}

/// Every built-in profile, by name.
pub const PROFILES: &[BuiltinProfile] = &[
    BuiltinProfile {
        name: "marlin-mixing-2in1",
        path: "machine/profiles/marlin-mixing-2in1.toml",
        text: include_str!("../profiles/marlin-mixing-2in1.toml"),
    },
    BuiltinProfile {
        name: "marlin-toolchanger-2",
        path: "machine/profiles/marlin-toolchanger-2.toml",
        text: include_str!("../profiles/marlin-toolchanger-2.toml"),
    },
    BuiltinProfile {
        name: "rrf-dual-gantry-2",
        path: "machine/profiles/rrf-dual-gantry-2.toml",
        text: include_str!("../profiles/rrf-dual-gantry-2.toml"),
    },
    BuiltinProfile {
        name: "rrf-idex-2",
        path: "machine/profiles/rrf-idex-2.toml",
        text: include_str!("../profiles/rrf-idex-2.toml"),
    },
    BuiltinProfile {
        name: "rrf-two-systems-2",
        path: "machine/profiles/rrf-two-systems-2.toml",
        text: include_str!("../profiles/rrf-two-systems-2.toml"),
    },
];

/// The built-in profile called `name`.
pub fn get(name: &str) -> Option<&'static BuiltinProfile> {
    PROFILES.iter().find(|p| p.name == name)
}

/// The names, for messages.
pub fn names() -> String {
    PROFILES.iter().map(|p| p.name).collect::<Vec<_>>().join(", ")
}
