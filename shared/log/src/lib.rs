//! One set of logging macros for the ECU logic, whichever side it runs on — the idea of
//! Embassy's `fmt.rs`, as a crate instead of a file copied into every crate.
//!
//! - feature `defmt` (firmware): `info!` etc. are defmt's, compressed on the wire and
//!   filtered at compile time by `DEFMT_LOG`;
//! - feature `log` (simulation, host tools): they are the `log` crate's, so any logger
//!   (`env_logger`, a test capture) shows them;
//! - neither: they compile to nothing, but their arguments are still type-checked.
//!
//! Write format strings both backends accept: `{}` and `{:?}` with values that implement
//! `Display`/`Debug` and `defmt::Format` (numbers, `&str`, `bool`, the crates' own types,
//! which derive `defmt::Format` under their `defmt` feature).
//!
//! The backend is chosen by this crate's features, so it is the same for every crate in a
//! build. A caller needs no dependency on defmt or log: the macros bring the backend into
//! scope themselves.
#![no_std]

#[cfg(all(feature = "defmt", feature = "log"))]
compile_error!("autoplug-log: enable either the `defmt` or the `log` backend, not both");

#[doc(hidden)]
pub mod __backend {
    #[cfg(feature = "defmt")]
    pub use defmt;
    #[cfg(feature = "log")]
    pub use log;
}

/// The backend compiled in: `"defmt"`, `"log"` or `"none"`.
pub const BACKEND: &str = if cfg!(feature = "defmt") {
    "defmt"
} else if cfg!(feature = "log") {
    "log"
} else {
    "none"
};

macro_rules! define_level {
    ($d:tt $name:ident) => {
        #[cfg(feature = "defmt")]
        #[doc = concat!("Logs at level `", stringify!($name), "` (defmt backend).")]
        #[macro_export]
        macro_rules! $name {
            ($d($d t:tt)*) => {{
                // defmt's macros name `defmt::…` paths: bring it into scope for the caller.
                #[allow(unused_imports)]
                use $d crate::__backend::defmt;
                defmt::$name!($d($d t)*);
            }};
        }

        #[cfg(all(feature = "log", not(feature = "defmt")))]
        #[doc = concat!("Logs at level `", stringify!($name), "` (log backend).")]
        #[macro_export]
        macro_rules! $name {
            ($d($d t:tt)*) => {
                $d crate::__backend::log::$name!($d($d t)*)
            };
        }

        #[cfg(not(any(feature = "log", feature = "defmt")))]
        #[doc = concat!("Logs at level `", stringify!($name), "` (no backend: checks the arguments only).")]
        #[macro_export]
        macro_rules! $name {
            ($s:literal $d(, $d x:expr)* $d(,)?) => {{
                let _ = ($d(&$d x),*);
            }};
        }
    };
}

define_level!($ trace);
define_level!($ debug);
define_level!($ info);
define_level!($ warn);
define_level!($ error);
