//! The shipped module library and morphologies. They are embedded in the binary so that `kumi`
//! works from any directory; a user's own morphology file is read from disk.

use std::path::Path;

use crate::error::{ModelError, Problem};
use crate::module::Module;
use crate::morphology::Morphology;

/// (kind, TOML file name, TOML text, URDF text) of every shipped module.
const SHIPPED_MODULES: [(&str, &str, &str, &str); 3] = [
    (
        "arm",
        "arm.toml",
        include_str!("../modules/arm.toml"),
        include_str!("../modules/arm.urdf"),
    ),
    (
        "wheel",
        "wheel.toml",
        include_str!("../modules/wheel.toml"),
        include_str!("../modules/wheel.urdf"),
    ),
    (
        "hub",
        "hub.toml",
        include_str!("../modules/hub.toml"),
        include_str!("../modules/hub.urdf"),
    ),
];

/// (name, TOML text) of every shipped morphology.
pub const SHIPPED_MORPHOLOGIES: [(&str, &str); 4] = [
    ("arm", include_str!("../morphologies/arm.toml")),
    ("minimal", include_str!("../morphologies/minimal.toml")),
    ("dragon", include_str!("../morphologies/dragon.toml")),
    ("tricycle", include_str!("../morphologies/tricycle.toml")),
];

/// The module types a morphology can use.
#[derive(Debug, Clone)]
pub struct ModuleLibrary {
    modules: Vec<Module>,
}

impl ModuleLibrary {
    /// The modules shipped in `urdf/modules/`.
    pub fn shipped() -> Self {
        let modules = SHIPPED_MODULES
            .iter()
            .map(|(kind, file, toml_text, urdf_text)| {
                let module =
                    Module::parse(&format!("<shipped>/modules/{file}"), toml_text, urdf_text)
                        .unwrap_or_else(|e| panic!("shipped module `{kind}` is invalid: {e}"));
                assert_eq!(
                    &module.kind, kind,
                    "shipped module file {file} declares another kind"
                );
                module
            })
            .collect();
        Self { modules }
    }

    /// The module of this kind, if the library has it.
    pub fn get(&self, kind: &str) -> Option<&Module> {
        self.modules.iter().find(|m| m.kind == kind)
    }

    /// Every kind in the library, sorted.
    pub fn kinds(&self) -> Vec<String> {
        let mut kinds: Vec<_> = self.modules.iter().map(|m| m.kind.clone()).collect();
        kinds.sort();
        kinds
    }
}

/// Names of the shipped morphologies.
pub fn shipped_morphologies() -> Vec<&'static str> {
    SHIPPED_MORPHOLOGIES.iter().map(|(name, _)| *name).collect()
}

/// Loads a morphology by shipped name (`tricycle`) or by path to a TOML file.
pub fn load_morphology(
    name_or_path: &str,
    library: &ModuleLibrary,
) -> Result<Morphology, ModelError> {
    if let Some((name, text)) = SHIPPED_MORPHOLOGIES
        .iter()
        .find(|(n, _)| *n == name_or_path)
    {
        return Morphology::parse(
            &format!("<shipped>/morphologies/{name}.toml"),
            text,
            library,
        );
    }
    let path = Path::new(name_or_path);
    let text = std::fs::read_to_string(path).map_err(|e| {
        ModelError::new(
            name_or_path,
            "-",
            Problem::Unreadable(format!(
                "not a shipped morphology ({}) and not a readable file: {e}",
                shipped_morphologies().join(", ")
            )),
        )
    })?;
    Morphology::parse(&path.display().to_string(), &text, library)
}
