//! Mesh URIs as real robot descriptions write them (`package://pkg/meshes/a.stl`, `file:///abs`,
//! `meshes/a.stl` relative to the URDF), resolved without ROS through a package-directory map.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Where each ROS package named in `package://` URIs lives on this machine.
///
/// A package missing from the map is looked for by walking up from the URDF's folder to a folder
/// with the package's name, which finds the usual `my_pkg/urdf/robot.urdf` layout without help.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct PackageMap {
    dirs: BTreeMap<String, PathBuf>,
}

impl PackageMap {
    pub fn new() -> Self {
        Self::default()
    }

    /// Maps `package://name/...` to `dir/...`.
    pub fn insert(&mut self, name: impl Into<String>, dir: impl Into<PathBuf>) {
        self.dirs.insert(name.into(), dir.into());
    }

    /// Parses a command-line `NAME=DIR` argument.
    pub fn parse_entry(entry: &str) -> Result<(String, PathBuf), String> {
        match entry.split_once('=') {
            Some((name, dir)) if !name.is_empty() && !dir.is_empty() => {
                Ok((name.to_owned(), PathBuf::from(dir)))
            }
            _ => Err(format!(
                "package directory '{entry}' is not of the form NAME=DIR"
            )),
        }
    }

    /// Resolves a mesh URI to an existing file. `urdf_dir` is the folder of the URDF file, used for
    /// relative URIs and for finding packages by folder name; `None` for URDF text without a file.
    pub fn resolve(&self, uri: &str, urdf_dir: Option<&Path>) -> Result<PathBuf, String> {
        let path = if let Some(rest) = uri.strip_prefix("package://") {
            self.resolve_package(rest, urdf_dir)?
        } else if let Some(rest) = uri.strip_prefix("file://") {
            PathBuf::from(rest)
        } else if uri.contains("://") {
            return Err(format!(
                "mesh URI '{uri}' has a scheme other than package:// or file://"
            ));
        } else if Path::new(uri).is_absolute() {
            PathBuf::from(uri)
        } else {
            match urdf_dir {
                Some(dir) => dir.join(uri),
                None => {
                    return Err(format!(
                        "mesh URI '{uri}' is relative but the URDF was not read from a file"
                    ));
                }
            }
        };
        if path.is_file() {
            Ok(path)
        } else {
            Err(format!(
                "mesh '{uri}' resolves to '{}', which does not exist",
                path.display()
            ))
        }
    }

    fn resolve_package(&self, rest: &str, urdf_dir: Option<&Path>) -> Result<PathBuf, String> {
        let (package, relative) = rest.split_once('/').unwrap_or((rest, ""));
        if package.is_empty() {
            return Err(format!("mesh URI 'package://{rest}' names no package"));
        }
        if let Some(dir) = self.dirs.get(package) {
            return Ok(dir.join(relative));
        }
        let found = urdf_dir
            .into_iter()
            .flat_map(Path::ancestors)
            .find(|dir| dir.file_name().is_some_and(|name| name == package));
        match found {
            Some(dir) => Ok(dir.join(relative)),
            None => Err(format!(
                "package '{package}' (in 'package://{rest}') is not in the package map; pass --package-dir {package}=DIR"
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn entry_needs_name_and_dir() {
        assert_eq!(
            PackageMap::parse_entry("ur_description=/opt/ur").unwrap(),
            ("ur_description".to_owned(), PathBuf::from("/opt/ur"))
        );
        for bad in ["ur_description", "=dir", "name=", ""] {
            let message = PackageMap::parse_entry(bad).unwrap_err();
            assert!(message.contains("NAME=DIR"), "{message}");
        }
    }

    #[test]
    fn unknown_scheme_and_unknown_package_are_reported() {
        let map = PackageMap::new();
        let message = map.resolve("http://example.com/a.stl", None).unwrap_err();
        assert!(message.contains("scheme"), "{message}");
        let message = map.resolve("package://nowhere/a.stl", None).unwrap_err();
        assert!(message.contains("--package-dir nowhere=DIR"), "{message}");
        let message = map.resolve("meshes/a.stl", None).unwrap_err();
        assert!(message.contains("relative"), "{message}");
    }
}
