//! Keyword arguments as command-line options: `render(scene, k=4, raster_samples=16)` is
//! parsed as `splat render --k=4 --raster-samples=16` by the CLI's own argument definitions, so
//! every option has one declaration, one default and one check; errors come back with the
//! options spelled as Python spells them.

use crate::SplatError;
use clap::{Args, Parser};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyList, PyTuple};
use splat_cli::render::RenderArgs;

/// Options of type `T` parsed from keyword arguments.
pub struct Parsed<T>(pub T);

/// The parser of one group of options, without a program name.
#[derive(Parser)]
#[command(no_binary_name = true, disable_help_flag = true)]
struct Options<T: Args> {
    #[command(flatten)]
    inner: T,
}

/// The option `flag` (without dashes) as a keyword argument: dashes as underscores.
pub fn keyword(flag: &str) -> String {
    flag.replace('-', "_")
}

/// `message` with every `--flag` written as the keyword `flag=`, and clap's "error: " prefix,
/// value placeholders and usage lines (which speak of a command line) left out.
pub fn pythonic(message: &str) -> String {
    let lines = message.lines().filter(|l| !l.starts_with("Usage:") && !l.starts_with("For more information"));
    let text = lines.collect::<Vec<_>>().join("\n");
    let text = text.strip_prefix("error: ").unwrap_or(&text);
    flags_as_keywords(&without_placeholders(text)).trim().to_string()
}

/// `text` without clap's value placeholders (the ` <METHOD>` of `--method <METHOD>`).
fn without_placeholders(text: &str) -> String {
    let mut text = text.to_string();
    let mut from = 0;
    while let Some(open) = text[from..].find(" <").map(|at| from + at) {
        let close = text[open..].find('>').map(|at| open + at);
        match close {
            Some(close) if text[open + 2..close].chars().all(|c| c.is_ascii_uppercase() || c == '_') => {
                text.replace_range(open..=close, "");
            }
            _ => from = open + 2,
        }
    }
    text
}

/// `text` with every `--flag-name` written `flag_name=`.
fn flags_as_keywords(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(at) = rest.find("--") {
        out.push_str(&rest[..at]);
        let after = &rest[at + 2..];
        let end = after.find(|c: char| !(c.is_ascii_alphanumeric() || c == '-')).unwrap_or(after.len());
        if end == 0 {
            out.push_str("--");
        } else {
            out.push_str(&keyword(&after[..end]));
            out.push('=');
        }
        rest = &after[end..];
    }
    out.push_str(rest);
    out
}

/// The command-line form of a keyword argument's value: `None` and `False` leave the option
/// out, `True` gives the switch alone, a tuple or list its items joined by commas (a colour,
/// a point), anything else its `str()`.
fn argument(key: &str, value: &Bound<'_, PyAny>) -> PyResult<Option<String>> {
    let flag = format!("--{}", key.replace('_', "-"));
    if value.is_none() {
        return Ok(None);
    }
    if let Ok(switch) = value.cast::<PyBool>() {
        return Ok(switch.is_true().then_some(flag));
    }
    let items = if let Ok(list) = value.cast::<PyList>() {
        Some(list.iter().collect::<Vec<_>>())
    } else {
        value.cast::<PyTuple>().ok().map(|t| t.iter().collect())
    };
    let text = match items {
        Some(items) => items.iter().map(|v| v.str().map(|s| s.to_string())).collect::<PyResult<Vec<_>>>()?.join(","),
        None => value.str()?.to_string(),
    };
    Ok(Some(format!("{flag}={text}")))
}

/// Parse `kwargs` as options of type `T` for the function `what`.
pub fn parse<T: Args>(what: &str, kwargs: Option<&Bound<'_, PyDict>>) -> PyResult<Parsed<T>> {
    let mut argv = Vec::new();
    for (key, value) in kwargs.into_iter().flat_map(|d| d.iter()) {
        let key: String = key.extract()?;
        argv.extend(argument(&key, &value)?);
    }
    let matches = Options::<T>::try_parse_from(argv)
        .map_err(|e| SplatError::new_err(format!("{what}(): {}", pythonic(&e.to_string()))))?;
    Ok(Parsed(matches.inner))
}

/// Keyword arguments of `splat render`'s that name files to write: a Python render returns
/// its images instead.
const FILE_OUTPUTS: [&str; 5] = ["output", "all_cameras", "view_format", "variance", "alpha"];

/// `render`'s options, and which extra images a GPU render makes: `depth=True` and
/// `normal=True` ask for them (the CPU makes them always).
pub fn render_args<'py>(
    py: Python<'py>,
    kwargs: Option<&Bound<'py, PyDict>>,
) -> PyResult<(Parsed<RenderArgs>, splat_gpu::Extras)> {
    let mut extras = splat_gpu::Extras::default();
    let rest = PyDict::new(py);
    for (key, value) in kwargs.into_iter().flat_map(|d| d.iter()) {
        let name: String = key.extract()?;
        if FILE_OUTPUTS.contains(&name.as_str()) || name == "scene" {
            return Err(SplatError::new_err(format!(
                "render(): {name}= is not an option here: render returns every image as an array (write them with \
                 numpy or imageio), and takes the scene as its first argument"
            )));
        }
        match name.as_str() {
            "depth" => extras.depth = value.extract().map_err(|_| want_bool("depth"))?,
            "normal" => extras.normal = value.extract().map_err(|_| want_bool("normal"))?,
            _ => rest.set_item(key, value)?,
        }
    }
    Ok((parse("render", Some(&rest))?, extras))
}

fn want_bool(name: &str) -> PyErr {
    SplatError::new_err(format!("render(): {name}= takes True or False (whether a GPU render makes the image)"))
}
