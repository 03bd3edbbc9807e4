//! The CPU level: which compiled kernels run.
//!
//! Owns the one CPU feature level of the crate ([`CpuLevel`]), detected once
//! per process and capped by the environment variable `SHEARWARP_CPU`, the way
//! rav1e caps its CPU level:
//!
//! | `SHEARWARP_CPU` | kernels |
//! |---|---|
//! | `scalar` | the plain x86-64 build everywhere: `bsr`/`bsf` bit scans, plain shift loops |
//! | `avx2` | the depth search compiled for `lzcnt`/`tzcnt`, the shear's shift kernels for AVX2 (when the CPU has AVX2, LZCNT and BMI1) |
//! | unset or `native` | the best the CPU has |
//!
//! Every kernel compiled for a level has its plain reference beside it, and the
//! two give the same results bit for bit (the invariant tests compare them at
//! every level up to [`detected`]; CI runs the whole suite once more with
//! `SHEARWARP_CPU=scalar`). Objects that pick kernels ([`crate::render::Settings::cpu`],
//! [`crate::encode::mask::BinaryMask::set_cpu_level`]) default to [`level`] and
//! can be set lower, never above what the CPU has.
//!
//! [`reconstruct`] holds the reconstruction kernels between slices (linear,
//! Catmull–Rom) with the bound a cell must pass to possibly hold an iso value.

use std::sync::OnceLock;

pub mod reconstruct;

pub use reconstruct::Reconstruction;

use crate::error::{Error, Result};

/// A CPU feature level, ordered: a level runs on every CPU of a higher one.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum CpuLevel {
    /// The plain build (x86-64 baseline, or any other architecture).
    Scalar,
    /// AVX2 with LZCNT and BMI1 (x86-64-v3's integer part).
    Avx2,
}

impl CpuLevel {
    /// The name `SHEARWARP_CPU` and reports use.
    pub fn name(self) -> &'static str {
        match self {
            CpuLevel::Scalar => "scalar",
            CpuLevel::Avx2 => "avx2",
        }
    }

    /// Parses a level name (`native` is the detected level).
    pub fn parse(s: &str) -> Result<CpuLevel> {
        match s.trim().to_ascii_lowercase().as_str() {
            "scalar" | "plain" => Ok(CpuLevel::Scalar),
            "avx2" => Ok(CpuLevel::Avx2),
            "native" | "" => Ok(detected()),
            _ => Err(Error::value("SHEARWARP_CPU", format!("'{s}' (expected scalar, avx2 or native)"))),
        }
    }

    /// This level, lowered to what the CPU has.
    pub fn capped(self) -> CpuLevel {
        self.min(detected())
    }

    /// True when this level runs the kernels compiled for `lzcnt`/`tzcnt`/AVX2
    /// (and SSSE3).
    pub fn has_avx2(self) -> bool {
        self >= CpuLevel::Avx2
    }
}

/// The highest level this CPU supports (detected once).
pub fn detected() -> CpuLevel {
    static DETECTED: OnceLock<CpuLevel> = OnceLock::new();
    *DETECTED.get_or_init(|| {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::is_x86_feature_detected as has;
            // (every AVX2 CPU has SSSE3 too; the lean frame's gathers use it)
            if has!("avx2") && has!("lzcnt") && has!("bmi1") && has!("ssse3") {
                return CpuLevel::Avx2;
            }
        }
        CpuLevel::Scalar
    })
}

/// The level `SHEARWARP_CPU` asks for, if it is set: an error for a name that is
/// not a level (the command line reports it; [`level`] then runs the scalar
/// kernels, the safe choice).
pub fn env_override() -> Result<Option<CpuLevel>> {
    match std::env::var("SHEARWARP_CPU") {
        Ok(s) => CpuLevel::parse(&s).map(Some),
        Err(std::env::VarError::NotPresent) => Ok(None),
        Err(std::env::VarError::NotUnicode(_)) => Err(Error::value("SHEARWARP_CPU", "not valid UTF-8")),
    }
}

/// The process's CPU level: [`detected`], capped by `SHEARWARP_CPU` (decided once).
pub fn level() -> CpuLevel {
    static LEVEL: OnceLock<CpuLevel> = OnceLock::new();
    *LEVEL.get_or_init(|| match env_override() {
        Ok(Some(l)) => l.capped(),
        Ok(None) => detected(),
        Err(_) => CpuLevel::Scalar,
    })
}

/// Every level this CPU can run, lowest first (what the kernel tests compare).
pub fn all_levels() -> Vec<CpuLevel> {
    [CpuLevel::Scalar, CpuLevel::Avx2].into_iter().filter(|&l| l <= detected()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levels_parse_and_cap() {
        assert_eq!(CpuLevel::parse("scalar").unwrap(), CpuLevel::Scalar);
        assert_eq!(CpuLevel::parse(" AVX2 ").unwrap(), CpuLevel::Avx2);
        assert_eq!(CpuLevel::parse("native").unwrap(), detected());
        assert!(CpuLevel::parse("sse9").is_err());
        assert!(CpuLevel::Avx2.capped() <= detected());
        assert!(level() <= detected());
        assert_eq!(all_levels().first(), Some(&CpuLevel::Scalar));
        assert_eq!(all_levels().last(), Some(&detected()));
    }

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn detection_matches_the_cpu() {
        use std::arch::is_x86_feature_detected as has;
        assert_eq!(detected() == CpuLevel::Avx2, has!("avx2") && has!("lzcnt") && has!("bmi1") && has!("ssse3"));
    }
}
