//! Reads, checks and compiles the AutoPlug CAN database.
//!
//! The DBC file is the one place a message identifier, byte position or scale is written.
//! This crate runs on the host: `autoplug-can`'s build script uses it to turn the DBC into
//! the `no_std` codec the firmware and the simulation share, and host tools can use it to
//! read any DBC of the same dialect.

pub mod codegen;
pub mod lexer;
pub mod model;
pub mod parser;
pub mod validate;

pub use codegen::{generate, GenerateError};
pub use model::*;
pub use parser::parse;
pub use validate::{validate, ValidationError};

use std::fmt;

/// A syntax error, with the 1-based line and column where it was found.
#[derive(Clone, Debug, PartialEq)]
pub struct ParseError {
    /// Line.
    pub line: usize,
    /// Column.
    pub column: usize,
    /// What was wrong.
    pub message: String,
}

impl ParseError {
    /// A new error at a position.
    pub fn new(line: usize, column: usize, message: impl Into<String>) -> Self {
        Self {
            line,
            column,
            message: message.into(),
        }
    }
}

impl fmt::Display for ParseError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "line {}, column {}: {}",
            self.line, self.column, self.message
        )
    }
}

impl std::error::Error for ParseError {}
impl std::error::Error for ValidationError {}
impl std::error::Error for GenerateError {}

/// Everything that can stop a DBC from becoming code.
#[derive(Clone, Debug, PartialEq)]
pub enum Error {
    /// The text is not valid DBC.
    Parse(ParseError),
    /// The database contradicts itself.
    Invalid(Vec<ValidationError>),
    /// The database uses something the generator cannot express.
    Generate(GenerateError),
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Parse(e) => write!(f, "DBC syntax error at {e}"),
            Error::Invalid(errors) => {
                write!(f, "DBC is inconsistent ({} problems):", errors.len())?;
                for e in errors {
                    write!(f, "\n  {e}")?;
                }
                Ok(())
            }
            Error::Generate(e) => write!(f, "DBC cannot be generated: {e}"),
        }
    }
}

impl std::error::Error for Error {}

/// Parses and validates DBC text.
pub fn load(text: &str) -> Result<Database, Error> {
    let db = parse(text).map_err(Error::Parse)?;
    let problems = validate(&db);
    if problems.is_empty() {
        Ok(db)
    } else {
        Err(Error::Invalid(problems))
    }
}

/// Parses, validates and generates the codec source for DBC text.
pub fn compile(text: &str) -> Result<String, Error> {
    let db = load(text)?;
    generate(&db).map_err(Error::Generate)
}

#[cfg(test)]
mod tests;
