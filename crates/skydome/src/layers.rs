//! The layer check: the crate documentation's diagram (in `lib.rs`) is the layer table, and no
//! module may use a module drawn above it. Test modules (`#[cfg(test)]`) are not checked: a
//! test may build its inputs with any module (e.g. [`crate::synth`]).
//!
//! The diagram's lines read `a ─▶ b, c   description`: `─▶` goes one layer up, `,` stays on
//! the same layer, and a line that starts with `─▶` continues from the line above.

use std::collections::HashMap;
use std::path::Path;

/// Items of the crate root that every module may use.
const ROOT_ITEMS: &[&str] = &[
    "named_enum",
    "UnknownName",
    "VERSION",
    "HdrImage",
    "RgbImage",
];

/// Module name → layer (0 = lowest), from the first ```` ```text ```` block of `lib_rs`'s `//!`
/// documentation.
fn parse_diagram(lib_rs: &str) -> Result<HashMap<String, usize>, String> {
    let mut layers = HashMap::new();
    let mut inside = false;
    let mut layer = 0usize;
    let mut first = true;
    for line in lib_rs.lines() {
        let Some(doc) = line.strip_prefix("//!") else {
            continue;
        };
        let doc = doc.trim();
        if !inside {
            inside = doc == "```text";
            continue;
        }
        if doc.starts_with("```") {
            break;
        }
        // The modules, up to the description (three spaces or more).
        let names = doc.split("   ").next().unwrap_or("").trim();
        if names.is_empty() {
            continue;
        }
        let mut rest = names;
        if let Some(r) = rest.strip_prefix("─▶") {
            rest = r;
            layer += 1;
        } else if !first {
            return Err(format!(
                "diagram line '{doc}' neither starts the diagram nor ─▶"
            ));
        }
        first = false;
        for (i, step) in rest.split("─▶").enumerate() {
            layer += usize::from(i > 0);
            for name in step.split(',').map(str::trim).filter(|n| !n.is_empty()) {
                if layers.insert(name.to_string(), layer).is_some() {
                    return Err(format!("'{name}' appears twice in the diagram"));
                }
            }
        }
    }
    match layers.is_empty() {
        true => Err("no ```text diagram in the crate documentation".into()),
        false => Ok(layers),
    }
}

/// The `crate::name` paths used by the code in `src` (comments and test modules left out), as
/// `(line number, name)`; a group `crate::{a, b::c}` gives `a` and `b`.
fn crate_uses(src: &str) -> Vec<(usize, String)> {
    let mut out = Vec::new();
    let mut skip_to: Option<String> = None;
    let mut skip_next = false;
    let mut group: Option<(usize, i32)> = None;
    for (n, line) in src.lines().enumerate() {
        let n = n + 1;
        let trimmed = line.trim_start();
        if let Some(end) = &skip_to {
            if line == end {
                skip_to = None;
            }
            continue;
        }
        if skip_next {
            skip_next = false;
            if line.trim_end().ends_with('{') {
                let indent = &line[..line.len() - trimmed.len()];
                skip_to = Some(format!("{indent}}}"));
            }
            continue;
        }
        if trimmed.starts_with("#[cfg(test)]") {
            skip_next = true;
            continue;
        }
        if trimmed.starts_with("//") {
            continue;
        }
        let code = match line.find(" // ") {
            Some(i) => &line[..i],
            None => line,
        };
        let mut text = code;
        // Inside a group started on an earlier line: names at depth 1.
        if let Some((_, depth)) = group.as_mut() {
            let (names, end) = group_names(text, depth);
            out.extend(names.into_iter().map(|s| (n, s)));
            match end {
                Some(i) => {
                    group = None;
                    text = &text[i..];
                }
                None => continue,
            }
        }
        let mut at = 0;
        while let Some(i) = text[at..].find("crate::") {
            let start = at + i;
            at = start + "crate::".len();
            let before = text[..start].chars().next_back();
            if before.is_some_and(|c| c.is_alphanumeric() || c == '_' || c == '$') {
                continue;
            }
            let after = &text[at..];
            if let Some(inner) = after.strip_prefix('{') {
                let mut depth = 1;
                let (names, end) = group_names(inner, &mut depth);
                out.extend(names.into_iter().map(|s| (n, s)));
                match end {
                    Some(e) => at += 1 + e,
                    None => {
                        group = Some((n, depth));
                        break;
                    }
                }
                continue;
            }
            let name: String = after
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect();
            if !name.is_empty() {
                out.push((n, name));
            }
        }
    }
    out
}

/// The first path segments at depth 1 of a `{…}` group whose opening brace is already read
/// (`depth` ≥ 1 on entry), and the byte index just past the closing brace when it is on this
/// text.
fn group_names(text: &str, depth: &mut i32) -> (Vec<String>, Option<usize>) {
    let mut names = Vec::new();
    let mut expect_name = *depth == 1;
    let mut current = String::new();
    for (i, c) in text.char_indices() {
        match c {
            '{' => *depth += 1,
            '}' => {
                *depth -= 1;
                if *depth == 0 {
                    if !current.is_empty() {
                        names.push(std::mem::take(&mut current));
                    }
                    return (names, Some(i + 1));
                }
            }
            ',' if *depth == 1 => expect_name = true,
            c if expect_name && *depth == 1 && (c.is_alphanumeric() || c == '_') => current.push(c),
            _ if expect_name && !current.is_empty() => {
                names.push(std::mem::take(&mut current));
                expect_name = false;
            }
            _ => {}
        }
    }
    if !current.is_empty() {
        names.push(current);
    }
    (names, None)
}

/// The top-level module a source file belongs to (`sky/sun.rs` → `sky`), `None` for the crate
/// root and this check.
fn module_of(relative: &Path) -> Option<String> {
    let first = relative.components().next()?.as_os_str().to_str()?;
    let name = first.strip_suffix(".rs").unwrap_or(first);
    (!matches!(name, "lib" | "layers")).then(|| name.to_string())
}

/// Every way `module`'s source `src` breaks the layers: a use of a module drawn above it, or of
/// a name the diagram does not know.
fn violations(layers: &HashMap<String, usize>, file: &str, module: &str, src: &str) -> Vec<String> {
    let Some(&own) = layers.get(module) else {
        return vec![format!(
            "{file}: module '{module}' is not in the lib.rs diagram"
        )];
    };
    let mut out = Vec::new();
    for (line, name) in crate_uses(src) {
        match layers.get(&name) {
            Some(&l) if l > own => out.push(format!(
                "{file}:{line}: '{module}' (layer {own}) uses '{name}' (layer {l}), a higher layer"
            )),
            Some(_) => {}
            None if ROOT_ITEMS.contains(&name.as_str()) => {}
            None => out.push(format!(
                "{file}:{line}: 'crate::{name}' is neither a module in the lib.rs diagram nor a root item"
            )),
        }
    }
    out
}

fn source_files(dir: &Path, out: &mut Vec<std::path::PathBuf>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir)
        .expect("read src")
        .map(|e| e.expect("dir entry").path())
        .collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            source_files(&p, out);
        } else if p.extension().is_some_and(|e| e == "rs") {
            out.push(p);
        }
    }
}

fn src_dir() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src")
}

fn lib_rs() -> String {
    std::fs::read_to_string(src_dir().join("lib.rs")).expect("read lib.rs")
}

#[test]
fn no_module_uses_a_module_drawn_above_it() {
    let layers = parse_diagram(&lib_rs()).unwrap();
    let mut files = Vec::new();
    source_files(&src_dir(), &mut files);
    let mut all = Vec::new();
    let mut checked = 0;
    for path in &files {
        let relative = path.strip_prefix(src_dir()).unwrap();
        let Some(module) = module_of(relative) else {
            continue;
        };
        let src = std::fs::read_to_string(path).unwrap();
        all.extend(violations(
            &layers,
            &relative.display().to_string(),
            &module,
            &src,
        ));
        checked += 1;
    }
    assert!(checked > 30, "only {checked} files found under src/");
    assert!(all.is_empty(), "layer violations:\n{}", all.join("\n"));
}

#[test]
fn the_diagram_names_every_module() {
    let lib = lib_rs();
    let layers = parse_diagram(&lib).unwrap();
    let mut declared = Vec::new();
    let mut test_only = false;
    for line in lib.lines().map(str::trim) {
        let decl = line
            .strip_prefix("pub mod ")
            .or_else(|| line.strip_prefix("mod "))
            .and_then(|m| m.strip_suffix(';'));
        if let (Some(m), false) = (decl, test_only) {
            declared.push(m.to_string());
        }
        test_only = line == "#[cfg(test)]";
    }
    assert!(declared.len() > 20, "{declared:?}");
    let missing: Vec<_> = declared
        .iter()
        .filter(|m| !layers.contains_key(*m))
        .collect();
    assert!(
        missing.is_empty(),
        "modules missing from the lib.rs diagram: {missing:?}"
    );
    let unknown: Vec<_> = layers.keys().filter(|m| !declared.contains(m)).collect();
    assert!(
        unknown.is_empty(),
        "the diagram names modules lib.rs does not declare: {unknown:?}"
    );
}

#[test]
fn an_upward_use_is_caught_and_a_downward_one_is_not() {
    let lib = "//! ```text\n//! image   pixels\n//!   ─▶ sky ─▶ formats, plot   geometry\n//! ─▶ pipeline   runs it\n//! ```\n";
    let layers = parse_diagram(lib).unwrap();
    assert_eq!(layers["image"], 0);
    assert_eq!(layers["sky"], 1);
    assert_eq!((layers["formats"], layers["plot"]), (2, 2));
    assert_eq!(layers["pipeline"], 3);
    let down = "use crate::image::Circle;\nuse crate::{formats::HdrMeta, plot};\n";
    assert!(violations(&layers, "plot.rs", "plot", down).is_empty());
    let up = "use crate::image::Circle;\nfn f() { crate::pipeline::run(); }\n";
    let v = violations(&layers, "sky.rs", "sky", up);
    assert_eq!(v.len(), 1, "{v:?}");
    assert!(
        v[0].contains("sky.rs:2") && v[0].contains("'pipeline'"),
        "{v:?}"
    );
    let grouped = "use crate::{\n    image::Circle,\n    pipeline::{run, Options},\n};\n";
    let v = violations(&layers, "sky.rs", "sky", grouped);
    assert_eq!(v.len(), 1, "{v:?}");
    assert!(v[0].contains("sky.rs:3"), "{v:?}");
    // Comments, `$crate` and test modules do not count; unknown names do.
    let quiet = "// crate::pipeline\n/// [`crate::pipeline::run`]\n#[cfg(test)]\nmod tests {\n    use crate::pipeline::run;\n}\n";
    assert!(violations(&layers, "sky.rs", "sky", quiet).is_empty());
    let unknown = "use crate::nowhere::X;\n";
    assert_eq!(violations(&layers, "sky.rs", "sky", unknown).len(), 1);
    assert_eq!(violations(&layers, "new.rs", "new", "").len(), 1);
}
