//! Reads a plugin file as an object file, before the dynamic loader sees it: nothing of
//! the library runs until its format, entry symbol and ABI note say it can be loaded.

use std::path::Path;

use super::abi::*;
use super::refusal::refuse;
use crate::error::Result;

/// Refuses a file that is not a loadable plugin of this host: not a library of this
/// platform, truncated (the loader would map pages past its end, and touching them
/// kills the process with SIGBUS), without an entry symbol, or whose ABI note names
/// another ABI, layout or message set. Nothing of the library runs here.
pub fn inspect(path: &Path) -> Result<()> {
    entry_symbol(path, false).map(drop)
}

/// A plugin library's entry symbol and the ABI minor version its note declares.
pub(crate) struct Entry {
    pub symbol: String,
    pub minor: u32,
}

/// Largest plugin library read.
const MAX_LIBRARY_BYTES: u64 = 1 << 30;

/// [`inspect`], giving the entry symbol to look up. A library that runs `apart`, in a
/// process of its own, may abort on panics: that ends its process only.
pub(crate) fn entry_symbol(path: &Path, apart: bool) -> Result<Entry> {
    use object::{Object, ObjectSection, ObjectSegment};
    // A plugin library is a regular file; a device or FIFO in its place would be read
    // without end. 1 GiB is far above any plugin.
    let data = crate::source::read_regular(path, MAX_LIBRARY_BYTES)
        .map_err(|e| refuse(path, format!("cannot read: {e}")))?;
    let file = object::File::parse(&*data).map_err(|e| {
        refuse(
            path,
            format!("not a complete shared library of this platform (truncated, or of another format): {e}"),
        )
    })?;
    let size = data.len() as u64;
    for segment in file.segments() {
        let (offset, length) = segment.file_range();
        if offset.checked_add(length).is_none_or(|end| end > size) {
            return Err(refuse(
                path,
                format!(
                    "truncated: a segment needs bytes {offset}..{} of the file, which has {size}",
                    offset.saturating_add(length)
                ),
            ));
        }
    }
    let exports = file
        .exports()
        .map_err(|e| refuse(path, format!("cannot read its exported symbols: {e}")))?;
    let entries: Vec<String> = exports
        .iter()
        .filter_map(|e| {
            let name = e.name();
            let name = name
                .strip_prefix(b"_")
                .filter(|n| n.starts_with(ENTRY_PREFIX.as_bytes()))
                .unwrap_or(name);
            name.starts_with(ENTRY_PREFIX.as_bytes())
                .then(|| String::from_utf8_lossy(name).into_owned())
        })
        .collect();
    let symbol = match entries.as_slice() {
        [one] => one.clone(),
        [] => {
            return Err(refuse(
                path,
                format!(
                    "not a Lamina plugin: it exports no `{ENTRY_PREFIX}<name>` (use lamina_api::export_plugin!)"
                ),
            ));
        }
        several => {
            return Err(refuse(
                path,
                format!(
                    "it exports several plugins ({}): a library is one plugin",
                    several.join(", ")
                ),
            ));
        }
    };
    let name = &symbol[ENTRY_PREFIX.len()..];
    let section_name = ABI_SECTION.rsplit(',').next().unwrap_or(ABI_SECTION);
    let note = file
        .section_by_name(section_name)
        .and_then(|s| s.data().ok())
        .and_then(AbiNote::parse)
        .ok_or_else(|| {
            refuse(
                path,
                format!(
                    "plugin `{name}` carries no ABI note (section `{ABI_SECTION}`): rebuild it against lamina-api {}",
                    crate::VERSION
                ),
            )
        })?;
    if note.magic != PLUGIN_MAGIC {
        return Err(refuse(
            path,
            format!("plugin `{name}`: its ABI note is not a Lamina plugin's"),
        ));
    }
    check_note(path, name, &note, apart)?;
    Ok(Entry {
        minor: note.abi_minor,
        symbol,
    })
}

/// Checks a plugin's ABI note: its versions, and that its panics unwind unless it runs
/// `apart`.
fn check_note(path: &Path, name: &str, note: &AbiNote, apart: bool) -> Result<()> {
    check(
        path,
        name,
        &Declared {
            abi_major: note.abi_major,
            abi_minor: note.abi_minor,
            layout: note.layout,
            wire: note.wire,
            core_version: Some(&note.core_version),
        },
    )?;
    if !note.unwinds && !apart {
        return Err(refuse(
            path,
            format!(
                "plugin `{name}` was built with `panic = \"abort\"`: its first panic would end lamina with it; \
                 build it with panics that unwind (the default: remove `panic = \"abort\"` from its Cargo profile), \
                 or run it in a process of its own (--isolate-plugins)"
            ),
        ));
    }
    Ok(())
}

/// What a plugin declares about its build, from its note or its descriptor.
struct Declared<'a> {
    abi_major: u32,
    abi_minor: u32,
    layout: u64,
    wire: u64,
    core_version: Option<&'a str>,
}

fn check(path: &Path, name: &str, d: &Declared<'_>) -> Result<()> {
    let ours = format!(
        "lamina-api {} (plugin ABI {ABI_MAJOR}.0 to {ABI_MAJOR}.{ABI_MINOR})",
        crate::VERSION
    );
    let theirs = || {
        let built = d
            .core_version
            .map(|v| format!("lamina-api {v}, "))
            .unwrap_or_default();
        format!("{built}plugin ABI {}.{}", d.abi_major, d.abi_minor)
    };
    let rebuild = |what: String| {
        refuse(
            path,
            format!("plugin `{name}` {what}: rebuild it against this lamina's {ours}"),
        )
    };
    if d.abi_major != ABI_MAJOR {
        return Err(rebuild(format!(
            "was built against {}, whose messages and C types this lamina does not read",
            theirs()
        )));
    }
    if d.layout != LAYOUT_FINGERPRINT {
        return Err(rebuild(format!(
            "lays out the boundary's C types differently (layout fingerprint {:016x}, this lamina's {LAYOUT_FINGERPRINT:016x}; built against {})",
            d.layout,
            theirs()
        )));
    }
    let Some(&schema) = WIRE_SCHEMAS.get(d.abi_minor as usize) else {
        return Err(refuse(
            path,
            format!(
                "plugin `{name}` was built against {}, newer than this lamina's {ours}: upgrade lamina, or rebuild the plugin against this lamina-api",
                theirs()
            ),
        ));
    };
    if d.wire != schema {
        return Err(rebuild(format!(
            "exchanges messages other than those of plugin ABI {}.{} (schema {:016x}, expected {schema:016x}; it was built from a lamina-api whose messages changed without a new version)",
            d.abi_major, d.abi_minor, d.wire
        )));
    }
    Ok(())
}

/// Checks a descriptor's prefix once the library is loaded: the note could have lied.
pub(crate) fn check_descriptor(path: &Path, name: &str, prefix: &DescriptorPrefix) -> Result<()> {
    if prefix.magic != PLUGIN_MAGIC {
        return Err(refuse(
            path,
            "the entry point returned something that is not a Lamina plugin descriptor",
        ));
    }
    check(
        path,
        name,
        &Declared {
            abi_major: prefix.abi_major,
            abi_minor: prefix.abi_minor,
            layout: prefix.layout,
            wire: prefix.wire,
            core_version: None,
        },
    )?;
    if prefix.struct_size < std::mem::size_of::<PluginDescriptor>() {
        return Err(refuse(
            path,
            format!(
                "its descriptor has {} bytes, this lamina's has {}",
                prefix.struct_size,
                std::mem::size_of::<PluginDescriptor>()
            ),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn declared(minor: u32, wire: u64) -> Declared<'static> {
        Declared {
            abi_major: ABI_MAJOR,
            abi_minor: minor,
            layout: LAYOUT_FINGERPRINT,
            wire,
            core_version: Some("0.0.9"),
        }
    }

    fn refusal(d: &Declared<'_>) -> String {
        check(Path::new("p.so"), "p", d).expect_err("refused").to_string()
    }

    #[test]
    fn a_plugin_of_any_minor_up_to_ours_loads_when_its_messages_are_that_minors() {
        for (minor, &schema) in WIRE_SCHEMAS.iter().enumerate() {
            check(Path::new("p.so"), "p", &declared(minor as u32, schema)).expect("loads");
        }
    }

    #[test]
    fn a_plugin_whose_panics_abort_is_refused_unless_it_runs_apart() {
        let mut note = AbiNote::parse(&abi_note()).expect("note");
        check_note(Path::new("p.so"), "p", &note, false).expect("ours loads");
        note.unwinds = false;
        let e = check_note(Path::new("p.so"), "p", &note, false)
            .expect_err("refused")
            .to_string();
        assert!(e.contains("panic = \"abort\"") && e.contains("plugin `p`"), "{e}");
        assert!(e.contains("--isolate-plugins"), "{e}");
        check_note(Path::new("p.so"), "p", &note, true).expect("loads in a process of its own");
    }

    #[test]
    fn refusals_say_what_differs_and_what_to_do() {
        let newer = refusal(&declared(ABI_MINOR + 1, 1));
        assert!(
            newer.contains(&format!("plugin ABI {ABI_MAJOR}.{}", ABI_MINOR + 1))
                && newer.contains("newer than this lamina's")
                && newer.contains("upgrade lamina"),
            "{newer}"
        );
        let changed = refusal(&declared(ABI_MINOR, WIRE_FINGERPRINT ^ 1));
        assert!(
            changed.contains("changed without a new version")
                && changed.contains(&format!("{WIRE_FINGERPRINT:016x}"))
                && changed.contains("rebuild it against this lamina's lamina-api"),
            "{changed}"
        );
        let older = refusal(&Declared {
            abi_major: ABI_MAJOR - 1,
            ..declared(0, WIRE_FINGERPRINT)
        });
        assert!(
            older.contains(&format!("lamina-api 0.0.9, plugin ABI {}.0", ABI_MAJOR - 1))
                && older.contains(&format!("plugin ABI {ABI_MAJOR}.0 to {ABI_MAJOR}.{ABI_MINOR}")),
            "{older}"
        );
    }
}
