//! A user's URDF or MJCF read as XML with the limits a hostile file needs:
//! nesting no deeper than a robot's (the readers walk bodies recursively,
//! and 200 000 nested elements overflowed the stack), a bounded node count,
//! and no number that is not finite (`pos="nan 0 0.39"` passed the
//! kinematics check and came out as `NaN` inertials in the export).

/// The deepest nesting read. A robot's MJCF nests a body per joint inside
/// a handful of wrappers: a 50-joint chain is about 60 deep.
pub const MAX_DEPTH: usize = 512;
/// The most XML nodes read (a large robot's URDF or MJCF has a few
/// thousand; meshes are separate files).
pub const MAX_NODES: u32 = 2_000_000;

/// Attributes that hold names, not numbers: a link called `inf` is
/// allowed.
const NAMES: [&str; 16] = [
    "name",
    "link",
    "joint",
    "class",
    "childclass",
    "body",
    "site",
    "mesh",
    "material",
    "texture",
    "file",
    "filename",
    "type",
    "parent",
    "child",
    "version",
];

/// What is wrong in a user's URDF or MJCF, and where: the element as
/// written (its name with it), the attribute, what was found in it.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum XmlError {
    /// Not well-formed XML, or over [`MAX_NODES`].
    #[error("invalid XML: {0}")]
    Syntax(String),
    /// Elements nested deeper than [`MAX_DEPTH`], refused before parsing.
    #[error("elements nested over {MAX_DEPTH} deep (line {line}): no robot's file is; refused before reading it")]
    TooDeep { line: usize },
    /// A number attribute holding NaN or an infinity.
    #[error("{element} (line {line}), attribute `{attribute}`: `{found}` holds a number that is not finite")]
    NotFinite {
        element: String,
        line: u32,
        attribute: String,
        found: String,
    },
    /// An attribute whose value is not what its element needs.
    #[error("{element} {attribute}: `{found}` {expected}")]
    Value {
        element: String,
        attribute: String,
        found: String,
        /// What it must be, as said after the value ("is not 3 numbers").
        expected: String,
    },
    /// An element not read as written: one a reader does not take, an
    /// attribute missing, two that exclude each other.
    #[error("{element}: {problem}")]
    Element { element: String, problem: String },
    /// The document is not the format read.
    #[error("not an {format}: its root element is <{found}>")]
    Root { format: &'static str, found: String },
}

impl XmlError {
    /// `found` in `attribute` of `element` is not what it must be.
    pub fn value(element: &str, attribute: &str, found: &str, expected: impl Into<String>) -> XmlError {
        XmlError::Value {
            element: element.to_string(),
            attribute: attribute.to_string(),
            found: found.to_string(),
            expected: expected.into(),
        }
    }

    /// `element` is not read as written, because of `problem`.
    pub fn element(element: impl Into<String>, problem: impl Into<String>) -> XmlError {
        XmlError::Element {
            element: element.into(),
            problem: problem.into(),
        }
    }
}

/// `text` safe inside `<!-- … -->`: a comment may hold no "--" (names
/// come from the user's files: "--->" must not close it), nor end in "-".
pub fn comment(text: &str) -> String {
    let mut s = text.to_string();
    while s.contains("--") {
        s = s.replace("--", "- -");
    }
    if s.ends_with('-') {
        s.push(' ');
    }
    s
}

/// `text` parsed, or why not: too deep (the depth and the line),
/// malformed, too many nodes, or a non-finite number (the element, its
/// line and the attribute).
pub fn parse(text: &str) -> Result<roxmltree::Document<'_>, XmlError> {
    depth_within(text)?;
    let options = roxmltree::ParsingOptions {
        allow_dtd: false,
        nodes_limit: MAX_NODES,
    };
    let doc = roxmltree::Document::parse_with_options(text, options).map_err(|e| XmlError::Syntax(e.to_string()))?;
    for node in doc.descendants().filter(roxmltree::Node::is_element) {
        for a in node.attributes() {
            if NAMES.contains(&a.name()) {
                continue;
            }
            let tokens: Vec<Option<f64>> = a.value().split_whitespace().map(|t| t.parse::<f64>().ok()).collect();
            let numeric = !tokens.is_empty() && tokens.iter().all(Option::is_some);
            if numeric && tokens.iter().flatten().any(|x| !x.is_finite()) {
                let at = doc.text_pos_at(node.range().start);
                let named = node
                    .attribute("name")
                    .map(|n| format!(" name=\"{n}\""))
                    .unwrap_or_default();
                return Err(XmlError::NotFinite {
                    element: format!("<{}{named}>", node.tag_name().name()),
                    line: at.row,
                    attribute: a.name().to_string(),
                    found: a.value().to_string(),
                });
            }
        }
    }
    Ok(doc)
}

/// Refuses nesting deeper than [`MAX_DEPTH`] by one pass over the bytes,
/// before any parser recurses into it.
fn depth_within(text: &str) -> Result<(), XmlError> {
    let b = text.as_bytes();
    let (mut depth, mut line, mut i) = (0usize, 1usize, 0usize);
    let skip_to = |from: usize, end: &[u8]| -> usize {
        b[from..]
            .windows(end.len())
            .position(|w| w == end)
            .map_or(b.len(), |p| from + p + end.len())
    };
    while i < b.len() {
        match b[i] {
            b'\n' => {
                line += 1;
                i += 1;
            }
            b'<' if b[i..].starts_with(b"<!--") => i = skip_to(i, b"-->"),
            b'<' if b[i..].starts_with(b"<![CDATA[") => i = skip_to(i, b"]]>"),
            b'<' if b[i..].starts_with(b"<?") => i = skip_to(i, b"?>"),
            b'<' if b[i..].starts_with(b"<!") => i = skip_to(i, b">"),
            b'<' if b[i..].starts_with(b"</") => {
                depth = depth.saturating_sub(1);
                i = skip_to(i, b">");
            }
            b'<' => {
                // To the tag's end, past quoted attribute values.
                let mut j = i + 1;
                let mut quote = None;
                while j < b.len() {
                    match (quote, b[j]) {
                        (None, q @ (b'"' | b'\'')) => quote = Some(q),
                        (Some(q), c) if c == q => quote = None,
                        (None, b'>') => break,
                        (_, b'\n') => line += 1,
                        _ => {}
                    }
                    j += 1;
                }
                if j > 0 && j < b.len() && b[j - 1] != b'/' {
                    depth += 1;
                    if depth > MAX_DEPTH {
                        return Err(XmlError::TooDeep { line });
                    }
                }
                i = j + 1;
            }
            _ => i += 1,
        }
    }
    Ok(())
}

/// The indentation of the children of `element`: its first child
/// element's, else its own plus `step`.
pub fn indent(text: &str, element: &roxmltree::Node, step: &str) -> String {
    let line = |at: usize| {
        let start = text[..at].rfind('\n').map_or(0, |n| n + 1);
        let lead = &text[start..at];
        lead.chars().all(|c| c == ' ' || c == '\t').then(|| lead.to_string())
    };
    match element.children().find(|c| c.is_element()) {
        Some(c) => line(c.range().start).unwrap_or_else(|| step.repeat(2)),
        None => line(element.range().start).map_or_else(|| step.to_string(), |own| own + step),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// No name closes the comment it is written in, and what it says is
    /// read back by an XML parser as one comment.
    #[test]
    fn a_comment_holds_any_name() {
        for name in ["a--b", "--->", "x-->&<evil/>", "-", "----", "tail-"] {
            let said = comment(name);
            assert!(!said.contains("--") && !said.ends_with('-'), "{name:?} gave {said:?}");
            let doc = format!("<r><!-- {said} --></r>");
            let parsed = roxmltree::Document::parse(&doc).unwrap();
            assert_eq!(parsed.root_element().children().count(), 1, "{doc}");
        }
    }

    #[test]
    fn depth_is_counted_as_a_parser_would() {
        let nested = |n: usize| format!("{}{}", "<a x='>'>".repeat(n), "</a>".repeat(n));
        assert!(parse(&nested(MAX_DEPTH)).is_ok());
        let e = parse(&nested(MAX_DEPTH + 1)).unwrap_err().to_string();
        assert!(e.contains("nested over 512"), "{e}");
        let deep = format!("<robot>{}</robot>", nested(200_000));
        assert!(matches!(parse(&deep).unwrap_err(), XmlError::TooDeep { line: 1 }));
        // Empty elements, comments, CDATA and declarations do not nest.
        let flat = format!(
            "<?xml version='1.0'?><!DOCTYPE r><r>{}<!-- <a> --><![CDATA[<a>]]></r>",
            "<b/><c y=\"/\"/>".repeat(10_000)
        );
        assert!(depth_within(&flat).is_ok());
        assert_eq!(
            roxmltree::Document::parse(&nested(300)).unwrap().descendants().count(),
            301
        );
    }

    #[test]
    fn non_finite_numbers_are_refused_naming_element_and_attribute() {
        for (value, attr) in [
            ("nan 0 0.39", "pos"),
            ("0 0 inf", "pos"),
            ("-Infinity", "mass"),
            ("1e400", "mass"),
            ("NaN", "mass"),
        ] {
            let text = format!("<mujoco>\n<worldbody>\n<body name=\"b1\" {attr}=\"{value}\"/></worldbody></mujoco>");
            let e = parse(&text).unwrap_err().to_string();
            assert!(
                e.contains("<body name=\"b1\"> (line 3)") && e.contains(&format!("`{attr}`")),
                "{e}"
            );
        }
        // Names are names, whatever they spell; finite numbers pass.
        parse("<robot name='inf'><link name='nan'/><joint name='Infinity' type='revolute'><origin xyz='0 1e300 -2'/></joint></robot>").unwrap();
    }
}
