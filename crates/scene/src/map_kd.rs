//! The argument of an MTL `map_Kd` statement (DESIGN.md §5): options, then the file name, which
//! is the rest of the line and may contain spaces.
//!
//! Honoured: `-s` (scale) and `-o` (offset) of u and v, `-clamp`, and the defaults `-blendu on`,
//! `-blendv on` and `-cc off` (bilinear filtering, no colour correction). Every other option is
//! parsed, so the file name is found after it, and reported as ignored: the loader warns once
//! per scene for each. Parsed by the line check (so a malformed statement is a line-numbered
//! error) and again by [`MapLoader`], which reads and decodes the files.
//!
//! A texture that is missing, unreadable or undecodable is not an error: it gets one warning
//! naming the file, and every material using it keeps its `Kd`.

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::Vec2;

use crate::builder::SceneBuilder;
use crate::scene_file::SceneFiles;
use crate::settings::AlbedoRule;
use crate::texture::{DiffuseMap, Texture, Wrap};

/// A parsed `map_Kd` argument.
#[derive(Clone, Debug, PartialEq)]
pub struct MapStatement {
    /// The file, relative to its MTL file; backslashes (Windows exporters) read as slashes.
    pub file: String,
    pub scale: Vec2,
    pub offset: Vec2,
    pub wrap: Wrap,
    /// Options given that are not honoured, as written (`-bm`, `-blendu off`).
    pub ignored: Vec<String>,
}

/// What follows an option.
enum Arguments {
    /// Between `min` and `max` numbers.
    Numbers(usize, usize),
    /// `on` or `off`.
    Switch,
    /// One word (`-imfchan r`, `-type sphere`).
    Word,
}

fn arguments_of(option: &str) -> Option<Arguments> {
    Some(match option {
        "-s" | "-o" | "-t" => Arguments::Numbers(1, 3),
        "-mm" => Arguments::Numbers(2, 2),
        "-bm" | "-boost" | "-texres" => Arguments::Numbers(1, 1),
        "-clamp" | "-blendu" | "-blendv" | "-cc" => Arguments::Switch,
        "-imfchan" | "-type" => Arguments::Word,
        _ => return None,
    })
}

pub fn parse(argument: &str) -> Result<MapStatement, String> {
    let mut words = Words { rest: argument };
    let mut statement = MapStatement {
        file: String::new(),
        scale: Vec2::ONE,
        offset: Vec2::ZERO,
        wrap: Wrap::Repeat,
        ignored: Vec::new(),
    };
    while let Some(option) = words.peek().filter(|w| w.starts_with('-') && w.len() > 1) {
        words.next();
        match arguments_of(option) {
            Some(Arguments::Numbers(min, max)) => {
                let values = numbers(&mut words, option, min, max)?;
                let uv =
                    |default: f32| Vec2::new(values[0], values.get(1).copied().unwrap_or(default));
                match option {
                    "-s" => statement.scale = uv(1.0),
                    "-o" => statement.offset = uv(0.0),
                    _ => statement.ignored.push(option.to_owned()),
                }
            }
            Some(Arguments::Switch) => {
                let on = match words.next() {
                    Some("on") => true,
                    Some("off") => false,
                    _ => return Err(format!("map_Kd option {option} takes on or off")),
                };
                match (option, on) {
                    ("-clamp", true) => statement.wrap = Wrap::Clamp,
                    ("-clamp", false) => statement.wrap = Wrap::Repeat,
                    ("-blendu" | "-blendv", true) | ("-cc", false) => {}
                    _ => statement
                        .ignored
                        .push(format!("{option} {}", if on { "on" } else { "off" })),
                }
            }
            Some(Arguments::Word) => {
                words
                    .next()
                    .ok_or_else(|| format!("map_Kd option {option} needs a value"))?;
                statement.ignored.push(option.to_owned());
            }
            None => {
                // An option this parser does not know: its values are taken to be the numbers
                // and switches after it, so the file name is still found.
                while words
                    .peek()
                    .is_some_and(|w| w.parse::<f32>().is_ok() || w == "on" || w == "off")
                {
                    words.next();
                }
                statement.ignored.push(format!("{option} (unknown)"));
            }
        }
    }
    let file = words.rest.trim();
    if file.is_empty() {
        return Err("map_Kd needs a file name after its options".into());
    }
    statement.file = file.replace('\\', "/");
    Ok(statement)
}

/// A texture file read and decoded.
#[derive(Clone)]
struct TextureFile {
    texture: Arc<Texture>,
    /// BLAKE3 of the file's bytes.
    source: [u8; 32],
}

/// Reads the textures of a scene's `map_Kd` statements, each file once.
pub struct MapLoader<'a> {
    files: &'a dyn SceneFiles,
    rule: AlbedoRule,
    /// Each file by path: its texture and BLAKE3 of its bytes, or `None` when it failed (and
    /// was warned about).
    loaded: HashMap<PathBuf, Option<TextureFile>>,
    /// Options already warned about.
    warned: HashSet<String>,
}

impl<'a> MapLoader<'a> {
    pub fn new(files: &'a dyn SceneFiles, rule: AlbedoRule) -> MapLoader<'a> {
        MapLoader {
            files,
            rule,
            loaded: HashMap::new(),
            warned: HashSet::new(),
        }
    }

    /// The map of `material`'s `map_Kd` argument, its file relative to `dir` (its MTL file's
    /// folder); `None` (and a warning) when the texture cannot be used.
    pub fn load(
        &mut self,
        material: &str,
        argument: &str,
        dir: &Path,
        builder: &mut SceneBuilder,
    ) -> Option<DiffuseMap> {
        let statement = match parse(argument) {
            Ok(s) => s,
            Err(e) => {
                builder.warn(format!("material {material}: {e}; it keeps its Kd"));
                return None;
            }
        };
        for option in &statement.ignored {
            if self.warned.insert(option.clone()) {
                builder.warn(format!(
                    "map_Kd option {option} is not supported and is ignored (first met in \
                     material {material})"
                ));
            }
        }
        let path = dir.join(&statement.file);
        let TextureFile { texture, source } = self
            .loaded
            .entry(path.clone())
            .or_insert_with(|| read(self.files, &path, builder))
            .clone()?;
        Some(DiffuseMap {
            texture,
            scale: statement.scale,
            offset: statement.offset,
            wrap: statement.wrap,
            rule: self.rule,
            file: statement.file,
            source,
        })
    }
}

/// Reads and decodes one texture file; warns (once, as it is read once) when it cannot.
fn read(files: &dyn SceneFiles, path: &Path, builder: &mut SceneBuilder) -> Option<TextureFile> {
    let fallback = "its materials keep their Kd";
    let bytes = files
        .read(path)
        .map_err(|e| builder.warn(format!("texture {}: {e}; {fallback}", path.display())))
        .ok()?;
    let decoded = Texture::decode(&bytes, path)
        .map_err(|e| {
            builder.warn(format!(
                "texture {}: cannot be decoded ({e}); {fallback}",
                path.display()
            ))
        })
        .ok()?;
    if let Some((w, h)) = decoded.downscaled_from {
        let t = &decoded.texture;
        builder.note(format!(
            "texture {} is {w}×{h}, over the cap of {} texels a side: downscaled to {}×{}",
            path.display(),
            crate::texture::MAX_TEXTURE_SIDE,
            t.width(),
            t.height()
        ));
    }
    Some(TextureFile {
        texture: Arc::new(decoded.texture),
        source: *blake3::hash(&bytes).as_bytes(),
    })
}

/// `min` to `max` finite numbers; more numbers are left as the file name's start.
fn numbers(words: &mut Words, option: &str, min: usize, max: usize) -> Result<Vec<f32>, String> {
    let mut values = Vec::with_capacity(max);
    while values.len() < max {
        let Some(value) = words.peek().and_then(|w| w.parse::<f32>().ok()) else {
            break;
        };
        if !value.is_finite() {
            return Err(format!("map_Kd option {option} has a non-finite number"));
        }
        words.next();
        values.push(value);
    }
    if values.len() < min {
        return Err(format!(
            "map_Kd option {option} needs at least {min} number{}",
            if min == 1 { "" } else { "s" }
        ));
    }
    Ok(values)
}

/// Whitespace-separated words, with the untouched rest of the text after them.
struct Words<'a> {
    rest: &'a str,
}

impl<'a> Words<'a> {
    fn peek(&self) -> Option<&'a str> {
        self.rest.split_whitespace().next()
    }

    fn next(&mut self) -> Option<&'a str> {
        let trimmed = self.rest.trim_start();
        let end = trimmed.find(char::is_whitespace).unwrap_or(trimmed.len());
        self.rest = &trimmed[end..];
        (end > 0).then(|| &trimmed[..end])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_plain_file_name_with_spaces_and_backslashes() {
        let s = parse("  my textures\\old wall.png  ").expect("parses");
        assert_eq!(s.file, "my textures/old wall.png");
        assert_eq!(
            (s.scale, s.offset, s.wrap),
            (Vec2::ONE, Vec2::ZERO, Wrap::Repeat)
        );
        assert!(s.ignored.is_empty());
    }

    #[test]
    fn honoured_options_set_the_transform_and_the_wrap() {
        let s = parse("-s 2 3 1 -o 0.5 -clamp on -blendu on -cc off wall 2.jpg").expect("parses");
        assert_eq!(s.scale, Vec2::new(2.0, 3.0));
        assert_eq!(s.offset, Vec2::new(0.5, 0.0));
        assert_eq!(s.wrap, Wrap::Clamp);
        assert_eq!(s.file, "wall 2.jpg");
        assert!(s.ignored.is_empty(), "{:?}", s.ignored);
        assert_eq!(
            parse("-s 4 a.png").expect("parses").scale,
            Vec2::new(4.0, 1.0)
        );
    }

    #[test]
    fn other_options_are_skipped_and_reported() {
        let s = parse("-bm 0.5 -mm 0 1 -imfchan l -t 1 1 -blendv off -cc on -zz 3 on t.png")
            .expect("parses");
        assert_eq!(s.file, "t.png");
        assert_eq!(
            s.ignored,
            [
                "-bm",
                "-mm",
                "-imfchan",
                "-t",
                "-blendv off",
                "-cc on",
                "-zz (unknown)"
            ]
        );
    }

    #[test]
    fn malformed_statements_are_errors() {
        for (argument, message) in [
            ("-s 2 2", "map_Kd needs a file name after its options"),
            ("-clamp t.png", "map_Kd option -clamp takes on or off"),
            ("-bm t.png", "map_Kd option -bm needs at least 1 number"),
            ("-mm 1 t.png", "map_Kd option -mm needs at least 2 numbers"),
            ("-s inf t.png", "map_Kd option -s has a non-finite number"),
            ("-type", "map_Kd option -type needs a value"),
        ] {
            assert_eq!(parse(argument).expect_err(argument), message);
        }
    }
}
