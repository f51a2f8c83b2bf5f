//! A structure's build parameters as users type them: `key=value` pairs after the structure's
//! name (`--accel irregular:top=0.12,cell=2`, `--accel-params`, Python's `accel_params=`). As
//! pbrt-v4's `ParameterDictionary`: this file knows no structure and no key; each structure reads
//! its own keys (`AccelParams::read`, called from its `AccelStructure::build`) and refuses the
//! ones it does not know, so a new parameter is an edit to its structure's folder only.

use std::fmt;

use crate::{Error, Result};

/// `key=value` pairs, in the order given; empty means "every default".
#[derive(Debug, Clone, Default, PartialEq, Eq, Hash)]
pub struct AccelParams {
    pairs: Vec<(String, String)>,
}

impl AccelParams {
    /// No parameters: every structure's defaults.
    pub const NONE: AccelParams = AccelParams { pairs: Vec::new() };

    /// One pair (for programs that build a parameter set by hand).
    pub fn with(mut self, key: &str, value: impl fmt::Display) -> AccelParams {
        self.pairs.retain(|(k, _)| k != key);
        self.pairs.push((key.to_string(), value.to_string()));
        self
    }

    pub fn is_empty(&self) -> bool {
        self.pairs.is_empty()
    }

    /// The pairs of `more` added to these; a key given in both takes `more`'s value.
    pub fn merged(&self, more: &AccelParams) -> AccelParams {
        more.pairs.iter().fold(self.clone(), |p, (k, v)| p.with(k, v))
    }

    /// Reads the pairs as the structure `structure` (its registry name), which knows `keys`:
    /// `set(key, value)` for each pair in order. A key not in `keys`, or a value `set` refuses,
    /// is an error that names the structure, the pair and the accepted keys.
    pub fn read(
        &self,
        structure: &str,
        keys: &[&str],
        mut set: impl FnMut(&str, &str) -> std::result::Result<(), String>,
    ) -> Result<()> {
        let accepted = || {
            if keys.is_empty() {
                format!("'{structure}' takes no parameters")
            } else {
                format!("'{structure}' takes {}", keys.join(", "))
            }
        };
        for (k, v) in &self.pairs {
            if !keys.contains(&k.as_str()) {
                return Err(Error::InvalidInput(format!(
                    "accel parameter '{k}={v}': unknown key ({})",
                    accepted()
                )));
            }
            set(k, v).map_err(|e| Error::InvalidInput(format!("accel parameter '{k}={v}' of '{structure}': {e}")))?;
        }
        Ok(())
    }
}

impl std::str::FromStr for AccelParams {
    type Err = String;
    /// `key=value,key=value`, spaces around either ignored; empty is no parameters. Later pairs
    /// override earlier ones with the same key.
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        let mut p = AccelParams::NONE;
        for kv in s.split(',').map(str::trim).filter(|kv| !kv.is_empty()) {
            let (k, v) = kv
                .split_once('=')
                .ok_or_else(|| format!("accel parameter '{kv}' is not KEY=VALUE"))?;
            let (k, v) = (k.trim(), v.trim());
            if k.is_empty() || v.is_empty() {
                return Err(format!("accel parameter '{kv}' is not KEY=VALUE"));
            }
            p = p.with(k, v);
        }
        Ok(p)
    }
}

impl fmt::Display for AccelParams {
    /// The form `FromStr` reads: `key=value,key=value`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, (k, v)) in self.pairs.iter().enumerate() {
            if i > 0 {
                f.write_str(",")?;
            }
            write!(f, "{k}={v}")?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_prints_and_reads() {
        let p: AccelParams = " top = 0.5, cell=2 ,top=0.25".parse().unwrap();
        assert_eq!(p.to_string(), "cell=2,top=0.25");
        assert_eq!(p.to_string().parse::<AccelParams>(), Ok(p.clone()));
        assert!("".parse::<AccelParams>().unwrap().is_empty());
        for bad in ["top", "=1", "top=", "a=1,,b"] {
            let r = bad.parse::<AccelParams>();
            assert!(bad == "a=1,,b" || r.is_err(), "{bad}: {r:?}");
        }
        let mut seen = Vec::new();
        p.read("irregular", &["top", "cell"], |k, v| {
            seen.push(format!("{k}:{v}"));
            Ok(())
        })
        .unwrap();
        assert_eq!(seen, ["cell:2", "top:0.25"]);
        let e = p.read("bvh", &[], |_, _| Ok(())).unwrap_err().to_string();
        assert!(e.contains("'cell=2'") && e.contains("'bvh' takes no parameters"), "{e}");
        let e = p.read("grid", &["res"], |_, _| Ok(())).unwrap_err().to_string();
        assert!(e.contains("'grid' takes res"), "{e}");
        let e = p.read("irregular", &["top", "cell"], |_, _| Err("bad number".into()));
        assert!(
            e.unwrap_err()
                .to_string()
                .contains("'cell=2' of 'irregular': bad number")
        );
        assert_eq!(
            p.merged(&"top=1,alpha=2".parse().unwrap()).to_string(),
            "cell=2,top=1,alpha=2"
        );
    }
}
