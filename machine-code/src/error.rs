//! The errors of the machine-code analyses: a bad image, a missing symbol, code the decoder cannot
//! follow. A bound that cannot be given is not an error but a declined [`Bound`](crate::Bound).
use std::fmt;

/// Why an image could not be analysed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Error {
    /// The file could not be read.
    Io { path: String, message: String },
    /// The bytes are not an ELF image `object` can parse.
    Malformed(String),
    /// The image is not for a 32-bit ARM core.
    NotArm(String),
    /// No function of that name in the image's symbols.
    MissingSymbol(String),
    /// An instruction the decoder does not know, at `address` in `function`.
    Undecodable { function: String, address: u64 },
    /// Control flow the analysis cannot follow (a branch out of the code, a write of PC it cannot
    /// resolve).
    Unfollowable {
        function: String,
        address: u64,
        what: String,
    },
    /// A bounds file that does not parse or names nothing usable.
    Bounds(String),
    /// Anything else the analysis cannot proceed from (named).
    Other(String),
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Io { path, message } => write!(f, "reading {path}: {message}"),
            Error::Malformed(m) => write!(f, "not a readable ELF image: {m}"),
            Error::NotArm(m) => write!(f, "not an ARM image: {m}"),
            Error::MissingSymbol(s) => write!(f, "no function `{s}` in the image"),
            Error::Undecodable { function, address } => write!(
                f,
                "{function}: the instruction at {address:#010x} does not decode as Thumb-2"
            ),
            Error::Unfollowable {
                function,
                address,
                what,
            } => write!(f, "{function}: cannot follow {what} at {address:#010x}"),
            Error::Bounds(m) => write!(f, "bounds file: {m}"),
            Error::Other(m) => f.write_str(m),
        }
    }
}

impl std::error::Error for Error {}
