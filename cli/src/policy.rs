//! `kumi policy`: operations on policy files.
//!
//! `restamp`: moves a whole-body policy to its robot as it is now, without retraining. A
//! policy's contract carries the fingerprint of the robot it was trained on, and loading
//! refuses it on any other. When the robot changes in a way the policy may still serve (such as
//! Tricycle's wheels following their legs' steering, `follow_steering`), this writes the current
//! fingerprint and keeps the one it was trained on under
//! `kumi.trained_morphology_fingerprint`, so the file says both. What the policy does on the
//! changed robot is then for `kumi eval whole-body` to measure.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use clap::{Args, Subcommand};
use kumi_policies::metadata;
use kumi_runtime::ModelFile;
use kumi_terms::contract::{
    self, MORPHOLOGY, MORPHOLOGY_FINGERPRINT, TRAINED_MORPHOLOGY_FINGERPRINT, WHOLE_BODY_FORMAT,
};

#[derive(Subcommand)]
pub enum PolicyCommand {
    /// Stamp a whole-body policy with its robot's current fingerprint, keeping the one it was
    /// trained on (for a robot changed after training; evaluate it afterwards).
    Restamp(RestampArgs),
}

#[derive(Args)]
pub struct RestampArgs {
    /// The whole-body policy file (ONNX).
    pub policy: PathBuf,
    /// Write the re-stamped file here instead of over `POLICY`.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// The robot: a shipped name or a morphology file whose `name` is the policy's (default:
    /// the shipped robot the policy names).
    #[arg(long)]
    pub morphology: Option<String>,
}

pub fn run(command: PolicyCommand) -> Result<()> {
    match command {
        PolicyCommand::Restamp(args) => restamp(args),
    }
}

fn restamp(args: RestampArgs) -> Result<()> {
    let path = &args.policy;
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    let file = ModelFile::decode(bytes)
        .map_err(anyhow::Error::msg)
        .with_context(|| format!("{} is not a policy file", path.display()))?;
    let meta = &file.metadata;
    let format = meta.get(metadata::FORMAT).map(String::as_str);
    if format != Some(WHOLE_BODY_FORMAT) {
        bail!(
            "{}: `{}` is {:?}, not a whole-body policy ({WHOLE_BODY_FORMAT})",
            path.display(),
            metadata::FORMAT,
            format.unwrap_or("missing")
        );
    }
    let robot = meta
        .get(MORPHOLOGY)
        .with_context(|| format!("{}: no `{MORPHOLOGY}` in its metadata", path.display()))?;
    let model = crate::sim::load_model(args.morphology.as_deref().unwrap_or(robot))?;
    if &model.name != robot {
        bail!(
            "{}: the policy is `{robot}`'s, the morphology `{}`'s",
            path.display(),
            model.name
        );
    }
    let current = contract::morphology_fingerprint(&model);
    let out = args.out.as_ref().unwrap_or(path);
    crate::output::check_file(out, "--out")?;
    if meta.get(MORPHOLOGY_FINGERPRINT) == Some(&current) {
        let done = if out == path {
            "nothing written".to_string()
        } else {
            std::fs::write(out, &file.bytes)
                .with_context(|| format!("writing {}", out.display()))?;
            format!("copied to {} unchanged", out.display())
        };
        println!(
            "{}: already stamped for `{robot}` as it is now ({current}); {done}",
            path.display()
        );
        return Ok(());
    }
    let (stamped, old) = file
        .restamp(
            MORPHOLOGY_FINGERPRINT,
            &current,
            TRAINED_MORPHOLOGY_FINGERPRINT,
        )
        .with_context(|| format!("re-stamping {}", path.display()))?;
    std::fs::write(out, stamped).with_context(|| format!("writing {}", out.display()))?;
    let trained = meta
        .get(TRAINED_MORPHOLOGY_FINGERPRINT)
        .unwrap_or(&old)
        .clone();
    println!(
        "{}: `{MORPHOLOGY_FINGERPRINT}` {old} -> {current} (`{robot}` as it is now); trained on \
         {trained} (`{TRAINED_MORPHOLOGY_FINGERPRINT}`). Not retrained: evaluate it with `kumi \
         eval whole-body {robot} --policy {}`",
        out.display(),
        out.display()
    );
    Ok(())
}
