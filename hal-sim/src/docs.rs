//! The guide's reference pages (`docs/src/reference/`), rendered from the code so that they
//! cannot drift from it: the `piezo` command line (from its clap definition), the firmware's
//! settings table, the controller registry, the serial commands (the protocol table of
//! `src/command.rs`) and the protocol's error codes.
//!
//! `hal-sim/tests/docs_reference.rs` renders them and fails when a committed page differs;
//! `UPDATE_DOCS=1 cargo test -p hal-sim --test docs_reference` rewrites them.

use std::fmt::Write as _;

use piezo_core::command::{Error, MAX_LEVELS, MAX_LINE, MAX_LINES, TABLE_ADD_MAX, TABLE_LEN};
use piezo_core::firmware::{Access, FFS, LAWS, SETTINGS};
use piezo_core::registry::{Family, ALIASES, FF_NAMES, LAW_NAMES};

/// The command that rewrites the pages, named on each of them.
pub const REGENERATE: &str = "UPDATE_DOCS=1 cargo test -p hal-sim --test docs_reference";

/// One generated page: its path under `docs/src/` and its text.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Page {
    pub path: &'static str,
    pub text: String,
}

/// Every reference page. `cli` is the `piezo` binary's command (`Cli::command()`),
/// `command_rs` the text of the core's `src/command.rs` (its module doc holds the protocol
/// table).
pub fn pages(cli: &clap::Command, command_rs: &str) -> Result<Vec<Page>, String> {
    Ok(vec![
        Page {
            path: "reference/cli.md",
            text: cli_page(cli),
        },
        Page {
            path: "reference/protocol.md",
            text: protocol_page(command_rs)?,
        },
        Page {
            path: "reference/settings.md",
            text: settings_page(),
        },
        Page {
            path: "reference/controllers.md",
            text: controllers_page(),
        },
        Page {
            path: "reference/errors.md",
            text: errors_page(),
        },
    ])
}

fn header(title: &str, source: &str) -> String {
    format!(
        "# {title}\n\n<!-- Generated from {source} by hal-sim/src/docs.rs; do not edit. \
         Regenerate: {REGENERATE} -->\n\n"
    )
}

/// Markdown text outside code spans: `<`, `>`, `*` and `|` escaped (a table cell stays one
/// cell, `<FILE>` stays visible); code spans are kept as they are.
fn md_text(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for (i, part) in s.split('`').enumerate() {
        if i > 0 {
            out.push('`');
        }
        if i % 2 == 1 {
            out.push_str(&part.replace('|', "\\|"));
        } else {
            for ch in part.chars() {
                match ch {
                    '<' => out.push_str("&lt;"),
                    '>' => out.push_str("&gt;"),
                    '*' => out.push_str("\\*"),
                    '|' => out.push_str("\\|"),
                    c => out.push(c),
                }
            }
        }
    }
    // An odd number of backticks would open a span that never closes.
    if s.matches('`').count() % 2 == 1 {
        out = out.replace('`', "'");
    }
    out
}

/// A table cell: one line, `<br>` between the help's paragraphs and lines.
fn cell(s: &str) -> String {
    s.trim()
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .map(md_text)
        .collect::<Vec<_>>()
        .join("<br>")
}

/// A value in a code span that may itself contain backticks or pipes.
fn code(s: &str) -> String {
    let s = s.replace('|', "\\|");
    if s.contains('`') {
        format!("`` {s} ``")
    } else {
        format!("`{s}`")
    }
}

// ---------------------------------------------------------------------------------------
// The command line.

/// The CLI reference: every subcommand (depth first, in the order clap lists them) with its
/// description, usage and arguments.
pub fn cli_page(cli: &clap::Command) -> String {
    let mut root = cli.clone();
    root.build();
    let mut out = header(
        "Command line",
        "the `piezo` binary's clap definition (hal-sim/src/bin/piezo.rs, hal-sim/src/cli/)",
    );
    out.push_str(
        "Every subcommand of `piezo`, with its options. `piezo <command> --help` prints the \
         same text.\n\n",
    );
    command_section(&mut out, &root, &[]);
    out
}

fn command_section(out: &mut String, cmd: &clap::Command, parents: &[&str]) {
    let mut path: Vec<&str> = parents.to_vec();
    path.push(cmd.get_name());
    let full = path.join(" ");
    let level = "#".repeat((path.len() + 1).min(6));
    let _ = writeln!(out, "{level} `{full}`\n");
    if let Some(about) = cmd.get_long_about().or(cmd.get_about()) {
        let _ = writeln!(out, "{}\n", paragraphs(&about.to_string()));
    }
    let usage = cmd.clone().render_usage().to_string();
    let usage = usage.trim().trim_start_matches("Usage:").trim();
    let _ = writeln!(out, "```text\n{usage}\n```\n");

    // clap's own `help` subcommand only repeats this page.
    let subs: Vec<&clap::Command> = cmd
        .get_subcommands()
        .filter(|s| !s.is_hide_set() && s.get_name() != "help")
        .collect();
    if !subs.is_empty() {
        out.push_str("| command | what |\n|---|---|\n");
        for s in &subs {
            let anchor = format!("{full} {}", s.get_name()).replace(' ', "-");
            let about = s.get_about().map(|a| a.to_string()).unwrap_or_default();
            let _ = writeln!(
                out,
                "| [`{}`](#{anchor}) | {} |",
                s.get_name(),
                cell(&about)
            );
        }
        out.push('\n');
    }

    let args: Vec<&clap::Arg> = cmd
        .get_arguments()
        .filter(|a| !a.is_hide_set())
        .filter(|a| !matches!(a.get_id().as_str(), "help" | "version"))
        .collect();
    if !args.is_empty() {
        out.push_str("| argument | default | meaning |\n|---|---|---|\n");
        for a in args {
            let _ = writeln!(
                out,
                "| {} | {} | {} |",
                arg_name(a),
                arg_default(a),
                arg_help(a)
            );
        }
        out.push('\n');
    }
    for s in subs {
        command_section(out, s, &path);
    }
}

/// Paragraphs of an about text, each one line of markdown.
fn paragraphs(s: &str) -> String {
    s.split("\n\n")
        .map(|p| md_text(&p.lines().map(str::trim).collect::<Vec<_>>().join(" ")))
        .collect::<Vec<_>>()
        .join("\n\n")
}

fn value_names(a: &clap::Arg) -> String {
    let names: Vec<String> = a
        .get_value_names()
        .map(|v| v.iter().map(|n| format!("<{n}>")).collect())
        .unwrap_or_else(|| vec![format!("<{}>", a.get_id().as_str().to_uppercase())]);
    names.join(" ")
}

fn arg_name(a: &clap::Arg) -> String {
    let takes_value = a.get_num_args().is_none_or(|n| n.takes_values());
    if a.is_positional() {
        return code(&value_names(a));
    }
    let mut flags = Vec::new();
    if let Some(s) = a.get_short() {
        flags.push(format!("-{s}"));
    }
    if let Some(l) = a.get_long() {
        flags.push(format!("--{l}"));
    }
    let mut name = flags.join(", ");
    let is_flag = matches!(
        a.get_action(),
        clap::ArgAction::SetTrue | clap::ArgAction::SetFalse | clap::ArgAction::Count
    );
    if takes_value && !is_flag {
        name.push(' ');
        name.push_str(&value_names(a));
    }
    code(&name)
}

fn arg_default(a: &clap::Arg) -> String {
    let is_flag = matches!(
        a.get_action(),
        clap::ArgAction::SetTrue | clap::ArgAction::SetFalse | clap::ArgAction::Count
    );
    let d: Vec<String> = a
        .get_default_values()
        .iter()
        .map(|v| v.to_string_lossy().into_owned())
        .collect();
    if d.is_empty() || is_flag {
        String::new()
    } else {
        code(&d.join(","))
    }
}

fn arg_help(a: &clap::Arg) -> String {
    let mut h = a
        .get_long_help()
        .or(a.get_help())
        .map(|h| cell(&h.to_string()))
        .unwrap_or_default();
    let values: Vec<String> = a
        .get_possible_values()
        .iter()
        .filter(|v| !v.is_hide_set())
        .map(|v| code(v.get_name()))
        .collect();
    if !values.is_empty() && !a.is_hide_possible_values_set() {
        if !h.is_empty() {
            h.push_str("<br>");
        }
        let _ = write!(h, "one of {}", values.join(", "));
    }
    if a.is_required_set() {
        h.push_str(if h.is_empty() {
            "required"
        } else {
            " (required)"
        });
    }
    if matches!(a.get_action(), clap::ArgAction::Append) {
        h.push_str(if h.is_empty() {
            "may be repeated"
        } else {
            " (may be repeated)"
        });
    }
    h
}

// ---------------------------------------------------------------------------------------
// The firmware's settings.

fn access(a: Access) -> &'static str {
    match a {
        Access::Limit => "limit",
        Access::ReadOnly => "read-only",
        Access::Model => "model",
        Access::Sensor => "sensor",
    }
}

/// The settings table (`src/firmware/settings.rs`).
pub fn settings_page() -> String {
    let mut out = header(
        "Settings",
        "the firmware's settings table (src/firmware/settings.rs)",
    );
    out.push_str(
        "The parameters of `get` and `set`, in the order `help` lists them. `set` refuses a \
         value outside the range with `err 8` before any other check; a model setting is then \
         checked by the core's constructors too, and the law and compensator are rebuilt and \
         installed bumplessly. Access `limit`: an output limit, checked against the other \
         limits; `model`: the hysteresis model, the open-loop scaling or a gain; `sensor`: a sensor check (guard band, stuck-code limit), changed in place; `read-only`: \
         fixed by the board's converters and rate (`get` only). `save` stores every setting \
         but the read-only ones.\n\n",
    );
    out.push_str(
        "| name | unit | sets | access | default | range (`set`) |\n|---|---|---|---|---|---|\n",
    );
    for s in SETTINGS.iter() {
        let (default, range) = match s.access {
            Access::ReadOnly => ("board".to_string(), "-".to_string()),
            _ => (format!("{}", s.default), format!("{} .. {}", s.min, s.max)),
        };
        let _ = writeln!(
            out,
            "| `{}` | {} | {} | {} | {} | {} |",
            s.name,
            md_text(s.unit),
            md_text(s.about),
            access(s.access),
            default,
            range
        );
    }
    out
}

// ---------------------------------------------------------------------------------------
// The controller registry.

/// The registry's names (`src/registry.rs`), where each runs, and `piezo sim --list`'s line.
pub fn controllers_page() -> String {
    let sim = crate::sim::controllers::registry();
    let sim_about = |name: &str| {
        sim.iter()
            .find(|e| e.name == name)
            .map(|e| md_text(e.about))
    };
    // A name `piezo sim` does not run is described by the one it is built from.
    let about = |name: &str| {
        sim_about(name).unwrap_or_else(|| {
            if name == "linear" {
                return "linear scaling of the reference (calibrated gain and offset): the \
                        feedforward of `open-loop` and of the plain laws"
                    .into();
            }
            let plain = name.strip_prefix("ff+").unwrap_or(name);
            let base = plain.strip_suffix("-gbw").unwrap_or(plain);
            let mut text = format!("`{base}`");
            if base != plain {
                text.push_str(" predicting with the GBW (000 eq. 3)");
            }
            if plain != name {
                text = format!("{text} adding the feedforward voltage");
            }
            text
        })
    };
    let in_sim = |name: &str| yes(sim.iter().any(|e| e.name == name));
    let mut out = header(
        "Controllers",
        "the controller registry (src/registry.rs), the firmware's law tables \
         (src/firmware/laws.rs) and piezo sim's registry (hal-sim/src/sim/controllers.rs)",
    );
    out.push_str(
        "One spelling for the firmware's `mode` and `ff`, `piezo sim --controller`, `piezo \
         serial` and this guide. A feedback law is its kind, `ff+` in front when it adds the \
         feedforward voltage, `-gbw` behind when it predicts with the GBW (000 eq. 3) instead \
         of the CBW. The firmware's `mode` runs a law with the compensator `ff` selects; \
         `piezo sim` runs a law with the linear feedforward, or a compensator alone.\n\n\
         ## Feedback laws\n\n",
    );
    out.push_str(
        "| name | adds feedforward | predicts with | firmware `mode` | `piezo sim` | what |\n\
         |---|---|---|---|---|---|\n",
    );
    for (law, name) in LAW_NAMES.iter() {
        let family = if !law.needs_model() {
            "-"
        } else {
            match law.family {
                Family::Cbw => "CBW",
                Family::Gbw => "GBW",
            }
        };
        let _ = writeln!(
            out,
            "| `{name}` | {} | {family} | {} | {} | {} |",
            yes(law.feedforward),
            yes(LAWS.contains(name)),
            in_sim(name),
            about(name)
        );
    }
    out.push_str(
        "\n## Feedforward compensators\n\n| name | firmware `ff` | `piezo sim` | what |\n\
         |---|---|---|---|\n",
    );
    for (_, name) in FF_NAMES.iter() {
        let _ = writeln!(
            out,
            "| `{name}` | {} | {} | {} |",
            yes(FFS.contains(name)),
            in_sim(name),
            about(name)
        );
    }
    out.push_str(
        "\n## Former names\n\n`piezo sim` still takes these, with a note on stderr.\n\n\
         | former name | name |\n|---|---|\n",
    );
    for (old, new) in ALIASES.iter() {
        let _ = writeln!(out, "| `{old}` | `{new}` |");
    }
    out
}

fn yes(b: bool) -> &'static str {
    if b {
        "yes"
    } else {
        "-"
    }
}

// ---------------------------------------------------------------------------------------
// The protocol.

/// The numbered errors (`src/command/error.rs`).
pub fn errors_page() -> String {
    let mut out = header(
        "Error codes",
        "the protocol's error table (src/command/error.rs)",
    );
    out.push_str(
        "A refused command answers `err <code> <message>` and changes nothing. The Python \
         client raises the exception of the error's name.\n\n\
         | code | name | message |\n|---|---|---|\n",
    );
    for e in Error::ALL {
        let _ = writeln!(out, "| {} | `{e:?}` | {} |", e.code(), md_text(e.message()));
    }
    out
}

/// The commands: the protocol table of `src/command.rs`'s module doc, its links to the code
/// replaced by their values or names, and the names `mode` and `ff` accept.
pub fn protocol_page(command_rs: &str) -> Result<String, String> {
    let doc: Vec<&str> = command_rs
        .lines()
        .filter_map(|l| l.strip_prefix("//!"))
        .map(|l| l.strip_prefix(' ').unwrap_or(l))
        .collect();
    let start = doc
        .iter()
        .position(|l| l.starts_with("| command | effect | reply |"))
        .ok_or("src/command.rs: no `| command | effect | reply |` table in its module doc")?;
    let table: Vec<&str> = doc[start..]
        .iter()
        .take_while(|l| l.starts_with('|'))
        .copied()
        .collect();
    let mut out = header(
        "Serial commands",
        "the protocol table of src/command.rs and the firmware's law tables \
         (src/firmware/laws.rs)",
    );
    let _ = write!(
        out,
        "One ASCII command per line, at most {MAX_LINE} bytes; one reply line per command \
         (`ok ...` or `err <code> <message>`, see [error codes](errors.md)). Parameters: \
         [settings](settings.md).\n\n"
    );
    for l in table {
        out.push_str(&code_links(l));
        out.push('\n');
    }
    let list = |names: &[&str]| {
        names
            .iter()
            .map(|n| format!("`{n}`"))
            .collect::<Vec<_>>()
            .join(" ")
    };
    let _ = write!(
        out,
        "\n## Names\n\n* `mode`: {}\n* `ff`: {}\n\nWhat each is: \
         [controllers](controllers.md).\n",
        list(&LAWS),
        list(&FFS)
    );
    Ok(out)
}

/// Rustdoc links (`` [`NAME`] ``, `` [`text`](path) ``) as plain code; the protocol's
/// constants as their values.
fn code_links(line: &str) -> String {
    let consts: [(&str, String); 5] = [
        ("MAX_LINE", MAX_LINE.to_string()),
        ("MAX_LEVELS", MAX_LEVELS.to_string()),
        ("MAX_LINES", MAX_LINES.to_string()),
        ("TABLE_ADD_MAX", TABLE_ADD_MAX.to_string()),
        ("TABLE_LEN", TABLE_LEN.to_string()),
    ];
    let mut out = String::with_capacity(line.len());
    let mut rest = line;
    while let Some(i) = rest.find("[`") {
        let Some(j) = rest[i + 2..].find("`]") else {
            break;
        };
        out.push_str(&rest[..i]);
        let name = &rest[i + 2..i + 2 + j];
        let mut after = &rest[i + 2 + j + 2..];
        // A link with an explicit target: `[`text`](path)`.
        if after.starts_with('(') {
            if let Some(k) = after.find(')') {
                after = &after[k + 1..];
            }
        }
        match consts.iter().find(|(n, _)| *n == name) {
            Some((_, v)) => out.push_str(v),
            None => {
                let short = name.rsplit("::").next().unwrap_or(name);
                let _ = write!(out, "`{short}`");
            }
        }
        rest = after;
    }
    out.push_str(rest);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_outside_code_is_escaped_inside_kept() {
        assert_eq!(
            md_text("a <FILE> `x <y>` b|c"),
            "a &lt;FILE&gt; `x <y>` b\\|c"
        );
        assert_eq!(cell("one\n\ntwo\n"), "one<br>two");
    }

    #[test]
    fn links_become_code_and_constants_values() {
        assert_eq!(
            code_links(
                "in 2..=[`MAX_LEVELS`] ([`crate::bulk`]: x, [`Budget`](crate::firmware::Budget))"
            ),
            format!("in 2..={MAX_LEVELS} (`bulk`: x, `Budget`)")
        );
    }

    #[test]
    fn every_setting_and_name_is_on_its_page() {
        let s = settings_page();
        assert!(SETTINGS
            .iter()
            .all(|x| s.contains(&format!("`{}`", x.name))));
        let c = controllers_page();
        assert!(LAW_NAMES.iter().all(|(_, n)| c.contains(&format!("`{n}`"))));
        assert!(FF_NAMES.iter().all(|(_, n)| c.contains(&format!("`{n}`"))));
        let e = errors_page();
        assert!(Error::ALL.iter().all(|x| e.contains(x.message())));
    }
}
