//! Errors of the model crate. Every error names the file, the field and the problem.

use std::fmt;

/// What is wrong with a field of a module or morphology description.
#[derive(Debug, Clone, PartialEq)]
pub enum Problem {
    /// The file is not valid TOML, or a value has the wrong type.
    Syntax(String),
    /// A required field is absent.
    Missing,
    /// A field that the format does not know (often a typo).
    UnknownField { known: Vec<String> },
    /// A module kind that the module library does not have.
    UnknownModule { kind: String, known: Vec<String> },
    /// A role that does not exist, or that this module kind cannot take.
    UnknownRole { role: String, allowed: Vec<String> },
    /// Two modules (or two entries) share one name.
    Duplicate { name: String },
    /// A mount that cannot be built (unknown parent or connector, connector in use, cycle, ...).
    BadMount(String),
    /// A value out of its valid range, or a list of the wrong length.
    BadValue(String),
    /// The module URDF itself is broken.
    BadUrdf(String),
    /// The file cannot be read.
    Unreadable(String),
}

impl fmt::Display for Problem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Problem::Syntax(msg) => write!(f, "invalid TOML: {msg}"),
            Problem::Missing => write!(f, "missing required field"),
            Problem::UnknownField { known } => {
                write!(f, "unknown field (known fields: {})", known.join(", "))
            }
            Problem::UnknownModule { kind, known } => {
                write!(
                    f,
                    "unknown module kind `{kind}` (known: {})",
                    known.join(", ")
                )
            }
            Problem::UnknownRole { role, allowed } => {
                write!(
                    f,
                    "unknown role `{role}` (allowed here: {})",
                    allowed.join(", ")
                )
            }
            Problem::Duplicate { name } => write!(f, "duplicate name `{name}`"),
            Problem::BadMount(msg) => write!(f, "bad mount: {msg}"),
            Problem::BadValue(msg) => write!(f, "bad value: {msg}"),
            Problem::BadUrdf(msg) => write!(f, "bad URDF: {msg}"),
            Problem::Unreadable(msg) => f.write_str(msg),
        }
    }
}

/// An error while loading modules or morphologies, or assembling a robot.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelError {
    /// The file at fault (a path, or `<shipped>/name.toml` for built-in files).
    pub file: String,
    /// The field at fault, as a path such as `module[2].mount.connector`; `-` for the whole file.
    pub field: String,
    pub problem: Problem,
}

impl fmt::Display for ModelError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.field == "-" {
            write!(f, "{}: {}", self.file, self.problem)
        } else {
            write!(f, "{}: {}: {}", self.file, self.field, self.problem)
        }
    }
}

impl std::error::Error for ModelError {}

impl ModelError {
    pub fn new(file: impl Into<String>, field: impl Into<String>, problem: Problem) -> Self {
        Self {
            file: file.into(),
            field: field.into(),
            problem,
        }
    }
}

/// Turns a TOML deserialisation error into a [`ModelError`] that names the field when TOML can.
pub(crate) fn from_toml(file: &str, err: toml::de::Error) -> ModelError {
    let msg = err.message().to_string();
    // serde's messages name the field in backticks: "missing field `kind`", "unknown field `x`, expected ...".
    let quoted = msg.split('`').nth(1).unwrap_or("-").to_string();
    let problem = if msg.starts_with("missing field") {
        Problem::Missing
    } else if msg.starts_with("unknown field") {
        let known = msg
            .split("expected")
            .nth(1)
            .map(|rest| {
                rest.split('`')
                    .skip(1)
                    .step_by(2)
                    .map(str::to_string)
                    .collect()
            })
            .unwrap_or_default();
        Problem::UnknownField { known }
    } else {
        Problem::Syntax(msg.clone())
    };
    let field = match problem {
        Problem::Syntax(_) => match err.span() {
            Some(span) => format!("bytes {}..{}", span.start, span.end),
            None => "-".to_string(),
        },
        _ => quoted,
    };
    ModelError::new(file, field, problem)
}
