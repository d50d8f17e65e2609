//! One spelling of every controller name (issue 14 item 2): the core's registry
//! (`piezo_core::registry`) is the source; the firmware's `mode`/`ff` lists, the protocol
//! documentation in `src/command.rs`, `piezo sim`'s controllers and the old `piezo sim` names
//! (aliases for one release) are checked against it. A name added or respelled in one place
//! and not the others fails here.
use hal_sim::sim::controllers::{find, registry};
use piezo_core::firmware::{FFS, LAWS};
use piezo_core::registry::{Controller, ALIASES};

/// The names the protocol doc lists after `* \`mode\`:` or `* \`ff\`:`.
fn doc_list(command: &str) -> Vec<String> {
    let doc = include_str!("../../src/command.rs");
    let prefix = format!("//! * `{command}`: ");
    let line = doc
        .lines()
        .find_map(|l| l.strip_prefix(&prefix))
        .unwrap_or_else(|| panic!("src/command.rs lists no `{command}` names"));
    line.split_whitespace()
        .map(|w| w.trim_matches('`').to_string())
        .collect()
}

#[test]
fn firmware_doc_and_simulator_use_the_registry_spelling() {
    for n in LAWS.iter().chain(FFS.iter()) {
        let c = Controller::from_name(n).unwrap_or_else(|| panic!("firmware name {n}"));
        assert_eq!(
            c.name(),
            *n,
            "firmware spells {n} otherwise than the registry"
        );
    }
    assert_eq!(doc_list("mode"), LAWS, "protocol doc vs firmware laws");
    assert_eq!(doc_list("ff"), FFS, "protocol doc vs firmware compensators");
    let sim = registry();
    assert!(sim.len() >= 20, "piezo sim lists {} controllers", sim.len());
    for e in &sim {
        let c = Controller::from_name(e.name)
            .unwrap_or_else(|| panic!("piezo sim controller {} is not in the registry", e.name));
        assert_eq!(c.name(), e.name, "piezo sim spells {} otherwise", e.name);
    }
    // The firmware's laws that piezo sim also runs have the same name there.
    for n in [
        "open-loop",
        "pid",
        "hgo-robust",
        "fts",
        "adrc",
        "nmpc",
        "ims-cbw",
    ] {
        assert!(find(n).is_some(), "piezo sim has no {n}");
    }
}

#[test]
fn old_simulator_names_still_select_the_same_controller() {
    for (old, new) in ALIASES {
        let e = find(old).unwrap_or_else(|| panic!("alias {old}"));
        assert_eq!(e.name, new);
    }
    assert!(find("no-such-controller").is_none());
}
