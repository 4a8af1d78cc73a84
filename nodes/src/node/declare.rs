//! One declaration per node parameter ([`ParamSpec`]: key, type and default, bound, unit,
//! description, whether the node takes a change while it runs), as `generate_parameter_library`
//! declares a ROS 2 C++ node's. Everything else comes from it: the keys a parameter file may
//! set for the node ([`keys`]), the descriptor on the node's parameter services
//! ([`super::live`]), and the typed, bounded value the node's settings read
//! ([`ParamSpec::f64`], [`ParamSpec::u64`], ...). Each node keeps its declarations in one
//! `PARAMS` table; tests/it/node_params_declared.rs checks launch_scripts/params.yaml, the
//! descriptors and the defaults against them.

use rpkm_transport::dds_params::ParamRange;

use super::params::{NodeParams, ParamError};

/// A parameter's type and default.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ParamDefault {
    /// A double.
    F64(f64),
    /// A non-negative integer.
    U64(u64),
    /// A boolean.
    Bool(bool),
    /// A string.
    Str(&'static str),
    /// A list of strings.
    Strs(&'static [&'static str]),
    /// A list of doubles.
    F64s(&'static [f64]),
    /// A group of values under the key (`geometry.l1`, `temperatures.temp_machine`): set in
    /// the parameter files only, each member read by the node's own reader.
    Group,
}

/// What a number must satisfy besides its type.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ParamBound {
    /// Any finite value (integers: any non-negative one).
    Any,
    /// A double > 0 (no upper bound: the descriptor has no range, the node's check says it).
    Positive,
    /// A double in `lo..=hi`: durations, rates and periods become a `Duration`, which a value
    /// from a file must not overflow.
    Within(f64, f64),
    /// An integer in `lo..=hi`: buffer sizes and counts are bounded before anything is
    /// allocated from them.
    Count(u64, u64),
}

/// One parameter of a node.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParamSpec {
    /// The key (`warn_percent`); a group's ends with `.` (`geometry.`).
    pub key: &'static str,
    /// Type and default.
    pub default: ParamDefault,
    /// What a number must satisfy.
    pub bound: ParamBound,
    /// Unit of a number (`s`, `m`, `µm`; empty for a count or a ratio).
    pub unit: &'static str,
    /// What it is, without unit and bound (the descriptor adds them).
    pub description: &'static str,
    /// Whether the node takes a change while it runs (else a change needs a restart).
    pub live: bool,
}

impl ParamSpec {
    /// A parameter whose change needs a restart, with no bound and no unit.
    pub const fn fixed(
        key: &'static str,
        default: ParamDefault,
        description: &'static str,
    ) -> Self {
        Self {
            key,
            default,
            bound: ParamBound::Any,
            unit: "",
            description,
            live: false,
        }
    }

    /// A parameter the node applies while it runs.
    pub const fn live(key: &'static str, default: ParamDefault, description: &'static str) -> Self {
        Self {
            live: true,
            ..Self::fixed(key, default, description)
        }
    }

    /// A group of values set in the parameter files (`geometry.`).
    pub const fn group(key: &'static str, description: &'static str) -> Self {
        Self::fixed(key, ParamDefault::Group, description)
    }

    /// The same parameter in `unit`.
    #[must_use]
    pub const fn unit(self, unit: &'static str) -> Self {
        Self { unit, ..self }
    }

    /// The same parameter bounded by `bound`.
    #[must_use]
    pub const fn bound(self, bound: ParamBound) -> Self {
        Self { bound, ..self }
    }

    /// The same parameter with another default (a default that depends on the node's
    /// backends: `views`).
    #[must_use]
    pub const fn with_default(self, default: ParamDefault) -> Self {
        Self { default, ..self }
    }

    /// The range of the ROS 2 descriptor.
    pub fn range(&self) -> ParamRange {
        match self.bound {
            ParamBound::Within(lo, hi) => ParamRange::Float(lo, hi),
            ParamBound::Count(lo, hi) => ParamRange::count((lo, hi)),
            ParamBound::Any | ParamBound::Positive => ParamRange::None,
        }
    }

    /// The description of the ROS 2 descriptor: what it is, its unit and its bound
    /// (`pace of a campaign file, Hz (0.001 to 1000000)`).
    pub fn describe(&self) -> String {
        let mut text = self.description.to_owned();
        if !self.unit.is_empty() {
            text.push_str(", ");
            text.push_str(self.unit);
        }
        let bound = match self.bound {
            ParamBound::Any => return text,
            ParamBound::Positive => "> 0".to_owned(),
            ParamBound::Within(lo, hi) => format!("{lo} to {hi}"),
            ParamBound::Count(lo, hi) => format!("{lo} to {hi}"),
        };
        format!("{text} ({bound})")
    }

    /// The unit as a range error writes it after a bound (` s`).
    fn unit_suffix(&self) -> String {
        if self.unit.is_empty() {
            String::new()
        } else {
            format!(" {}", self.unit)
        }
    }

    fn declared_as(&self, p: &NodeParams, what: &'static str) -> ParamError {
        p.invalid(self.key, what)
    }

    /// The double of `p` (the default where not set), checked against the bound.
    pub fn f64(&self, p: &NodeParams) -> Result<f64, ParamError> {
        let ParamDefault::F64(d) = self.default else {
            return Err(self.declared_as(p, "a value of its declared type (not a double)"));
        };
        match self.bound {
            ParamBound::Any => p.f64(self.key, d),
            ParamBound::Positive => p.positive(self.key, d),
            ParamBound::Within(lo, hi) => p.f64_in(self.key, d, (lo, hi), &self.unit_suffix()),
            ParamBound::Count(..) => Err(self.declared_as(p, "a double (declared as a count)")),
        }
    }

    /// The integer of `p` (the default where not set), checked against the bound.
    pub fn u64(&self, p: &NodeParams) -> Result<u64, ParamError> {
        let ParamDefault::U64(d) = self.default else {
            return Err(self.declared_as(p, "a value of its declared type (not an integer)"));
        };
        match self.bound {
            ParamBound::Count(lo, hi) => p.u64_in(self.key, d, (lo, hi)),
            _ => p.u64(self.key, d),
        }
    }

    /// The boolean of `p` (the default where not set).
    pub fn bool(&self, p: &NodeParams) -> Result<bool, ParamError> {
        match self.default {
            ParamDefault::Bool(d) => p.bool(self.key, d),
            _ => Err(self.declared_as(p, "a value of its declared type (not a boolean)")),
        }
    }

    /// The string of `p` (the default where not set).
    pub fn string(&self, p: &NodeParams) -> Result<String, ParamError> {
        match self.default {
            ParamDefault::Str(d) => p.string(self.key, d),
            _ => Err(self.declared_as(p, "a value of its declared type (not a string)")),
        }
    }

    /// The list of strings of `p` (the default where not set).
    pub fn strings(&self, p: &NodeParams) -> Result<Vec<String>, ParamError> {
        match self.default {
            ParamDefault::Strs(d) => p.strings(self.key, d),
            _ => Err(self.declared_as(p, "a value of its declared type (not strings)")),
        }
    }

    /// The list of doubles of `p` (the default where not set).
    pub fn f64s(&self, p: &NodeParams) -> Result<Vec<f64>, ParamError> {
        match self.default {
            ParamDefault::F64s(d) => p.f64s(self.key, d),
            _ => Err(self.declared_as(p, "a value of its declared type (not doubles)")),
        }
    }

    /// The default of a double (NaN for a parameter of another type).
    pub const fn default_f64(&self) -> f64 {
        match self.default {
            ParamDefault::F64(d) => d,
            _ => f64::NAN,
        }
    }

    /// The default of an integer (0 for a parameter of another type).
    pub const fn default_u64(&self) -> u64 {
        match self.default {
            ParamDefault::U64(d) => d,
            _ => 0,
        }
    }
}

/// The keys of `tables`, in order.
pub fn keys(tables: &[&[ParamSpec]]) -> Vec<&'static str> {
    tables
        .iter()
        .flat_map(|t| t.iter().map(|s| s.key))
        .collect()
}

/// The specs of `tables` that the parameter services declare (every one but the groups).
pub fn served(tables: &[&[ParamSpec]]) -> Vec<ParamSpec> {
    tables.iter().flat_map(|t| t.iter()).copied().collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    const RATE: ParamSpec = ParamSpec::fixed("rate_hz", ParamDefault::F64(1000.0), "pace")
        .unit("Hz")
        .bound(ParamBound::Within(1e-3, 1e6));

    #[test]
    fn the_descriptor_says_unit_and_bound_and_the_reader_holds_the_bound() {
        assert_eq!(RATE.describe(), "pace, Hz (0.001 to 1000000)");
        assert_eq!(RATE.range(), ParamRange::Float(1e-3, 1e6));
        let mut p = NodeParams::empty("ingest");
        assert_eq!(RATE.f64(&p).ok(), Some(1000.0), "the default");
        p.merge_text(
            "ingest:\n  ros__parameters:\n    rate_hz: 2.0e6\n",
            Path::new("p.yaml"),
        )
        .expect("yaml");
        let e = RATE.f64(&p).expect_err("above the bound");
        assert!(
            e.to_string().ends_with("expected 0.001 to 1000000 Hz"),
            "{e}"
        );
        let e = RATE.u64(&p).expect_err("declared as a double");
        assert!(e.to_string().contains("declared type"), "{e}");
    }
}
