//! Roles of a level's surfaces: what a mesh or material is to the bake beyond its geometry
//! (docs/levels.md, "Roles: sky shells, clip brushes and caulk").
//!
//! Game levels are not closed rooms of drawn surfaces. Engines wrap the playable space in a
//! shell they draw as sky, and levels carry clip brushes, trigger volumes, collision hulls
//! and faces the player never sees. Every production baker has the lever: Unity's
//! "Contribute GI" and "Cast Shadows" per renderer, Unreal's per-primitive flags and
//! Lightmass portals, Bakery's sky portals, Godot's GI mode per mesh. Here a triangle has one
//! [`Role`]:
//!
//! | role | texels | casts shadows, meets rays | for |
//! |---|---|---|---|
//! | `baked` (the default) | yes | yes | everything drawn |
//! | `sky` | no | no: a ray through it goes on, to the sky and the sun, as through an opening | a sky shell, a skybox |
//! | `skip` | no | no | clip brushes, triggers, collision hulls, editor meshes |
//! | `no-shadow` | yes | no | foliage cards, decals, glass a bake should see through |
//! | `occluder` | no | yes | caulk, faces never seen that still keep light out |
//!
//! A `sky` surface and a `skip` one are traced alike (neither is in the tree the rays walk);
//! they differ in what they say to the user and to `render` (a sky is drawn as the sky). A
//! ray through a sky shell goes on: geometry *outside* the shell, if a level has any, is then
//! seen through it — give that `skip` too.
//!
//! Where a role comes from, the later winning: the name defaults ([`default_role`]: a mesh,
//! material or texture named like `sky`, `clip`, `trigger` or `caulk`), then what the file
//! says (glTF `extras` `"guidebake_role"` on a node, mesh or material — a Blender custom
//! property of that name exports there), then the scene file's `[roles]`, then `prepare
//! --role`. `prepare` records each triangle's role in the texel file's triangle table, so
//! `bake` and `render` trace what `prepare` decided.

use std::fmt;

use super::{Material, Mesh};

/// What a triangle is to the bake (module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Role {
    /// Drawn: texels, and rays meet it.
    #[default]
    Baked,
    /// Drawn as the sky: no texels; rays pass through it to the sky.
    Sky,
    /// Left out of the bake: no texels, rays pass through it.
    Skip,
    /// Texels, but rays pass through it: it casts nothing.
    NoShadow,
    /// No texels, but rays meet it: it keeps light out.
    Occluder,
}

impl Role {
    /// Every role, in the order of [`Role::code`].
    pub const ALL: [Role; 5] = [
        Role::Baked,
        Role::Sky,
        Role::Skip,
        Role::NoShadow,
        Role::Occluder,
    ];

    /// Its name on the command line and in files.
    #[must_use]
    pub fn name(self) -> &'static str {
        match self {
            Role::Baked => "baked",
            Role::Sky => "sky",
            Role::Skip => "skip",
            Role::NoShadow => "no-shadow",
            Role::Occluder => "occluder",
        }
    }

    /// The role named `name` (case-insensitive; `_` for `-`).
    #[must_use]
    pub fn parse(name: &str) -> Option<Role> {
        let name = name.trim().to_ascii_lowercase().replace('_', "-");
        Role::ALL.into_iter().find(|r| r.name() == name)
    }

    /// Whether rays meet it (it is in the tree the bake traces).
    #[must_use]
    pub fn traced(self) -> bool {
        matches!(self, Role::Baked | Role::Occluder)
    }

    /// Whether it gets texels.
    #[must_use]
    pub fn has_texels(self) -> bool {
        matches!(self, Role::Baked | Role::NoShadow)
    }

    /// Whether `render` draws it.
    #[must_use]
    pub fn drawn(self) -> bool {
        self.has_texels()
    }

    /// Its code in the texel file's triangle table (0 for [`Role::Baked`]).
    #[must_use]
    pub fn code(self) -> u32 {
        Role::ALL.iter().position(|&r| r == self).unwrap_or(0) as u32
    }

    /// The role of `code`, if one.
    #[must_use]
    pub fn of_code(code: u32) -> Option<Role> {
        Role::ALL.get(code as usize).copied()
    }

    /// The role names, for messages: `baked, sky, skip, no-shadow, occluder`.
    #[must_use]
    pub fn names() -> String {
        Role::ALL.map(Role::name).join(", ")
    }
}

impl fmt::Display for Role {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// What a [`RoleRule`]'s pattern is matched against.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Target {
    /// A mesh's name or its material's name.
    Any,
    /// The mesh's name (glTF node or mesh, OBJ object or group).
    Mesh,
    /// The material's name.
    Material,
}

/// `ROLE=PATTERN`: every triangle whose mesh or material name matches `PATTERN` (a glob:
/// `*` any run, `?` one character, case-insensitive; `mesh:` or `material:` in front
/// restricts it to one kind of name) takes `ROLE`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RoleRule {
    /// The role given.
    pub role: Role,
    /// What the pattern matches.
    pub target: Target,
    /// The glob, lower-case.
    pub pattern: String,
}

impl RoleRule {
    /// Parses `ROLE=PATTERN` (module docs).
    ///
    /// # Errors
    /// A message saying what is wrong and what is accepted.
    pub fn parse(text: &str) -> Result<RoleRule, String> {
        let Some((role, pattern)) = text.split_once('=') else {
            return Err(format!(
                "\"{text}\" is not ROLE=PATTERN (e.g. sky=material:skybox*; roles: {})",
                Role::names()
            ));
        };
        let role = Role::parse(role)
            .ok_or_else(|| format!("\"{role}\" is not a role; the roles are {}", Role::names()))?;
        let (target, pattern) = match pattern.split_once(':') {
            Some(("mesh", p)) => (Target::Mesh, p),
            Some(("material", p)) => (Target::Material, p),
            _ => (Target::Any, pattern),
        };
        if pattern.is_empty() {
            return Err(format!("\"{text}\": the pattern is empty"));
        }
        Ok(RoleRule {
            role,
            target,
            pattern: pattern.to_lowercase(),
        })
    }

    /// Whether the rule names a triangle of `mesh` with `material`.
    #[must_use]
    pub fn matches(&self, mesh: &str, material: &str) -> bool {
        let hit = |name: &str| glob(&self.pattern, &name.to_lowercase());
        match self.target {
            Target::Any => hit(mesh) || hit(material),
            Target::Mesh => hit(mesh),
            Target::Material => hit(material),
        }
    }
}

impl fmt::Display for RoleRule {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let kind = match self.target {
            Target::Any => "",
            Target::Mesh => "mesh:",
            Target::Material => "material:",
        };
        write!(f, "{}={kind}{}", self.role, self.pattern)
    }
}

/// Whether `text` matches the glob `pattern` (`*` any run, `?` one character).
fn glob(pattern: &str, text: &str) -> bool {
    let p: Vec<char> = pattern.chars().collect();
    let t: Vec<char> = text.chars().collect();
    // Iterative matching with one backtrack point: linear in practice, never exponential.
    let (mut i, mut j) = (0, 0);
    let mut star: Option<(usize, usize)> = None;
    while j < t.len() {
        if i < p.len() && (p[i] == '?' || p[i] == t[j]) {
            i += 1;
            j += 1;
        } else if i < p.len() && p[i] == '*' {
            star = Some((i, j));
            i += 1;
        } else if let Some((si, sj)) = star {
            i = si + 1;
            j = sj + 1;
            star = Some((si, sj + 1));
        } else {
            return false;
        }
    }
    p[i..].iter().all(|&c| c == '*')
}

/// Words that make a name a `sky` by default (after trailing digits are cut: Quake's `sky1`).
pub const SKY_WORDS: [&str; 6] = ["sky", "skies", "skybox", "skydome", "skysphere", "skyshell"];
/// Words that make a name `skip` by default: clip brushes, triggers, hint and portal brushes,
/// collision hulls (Unreal's `UCX_`, `UBX_`, `UCP_`, `USP_` prefixes, Godot's `-colonly`).
pub const SKIP_WORDS: [&str; 18] = [
    "clip",
    "playerclip",
    "monsterclip",
    "botclip",
    "weapclip",
    "fullclip",
    "trigger",
    "hint",
    "skip",
    "areaportal",
    "clusterportal",
    "donotenter",
    "nodrop",
    "collision",
    "colonly",
    "ucx",
    "ubx",
    "ucp",
];
/// Words that make a name an `occluder` by default: Quake's caulk and nodraw, faces never
/// drawn that still keep light out.
pub const OCCLUDER_WORDS: [&str; 2] = ["caulk", "nodraw"];

/// The role `names` (a mesh's, its material's, the material's texture file) ask for by their
/// words (module docs, [`SKY_WORDS`], [`SKIP_WORDS`], [`OCCLUDER_WORDS`]), the first that
/// asks winning; `None` for names like any other.
///
/// A name is cut into words at every character that is not a letter or digit and where a
/// lower-case letter meets an upper-case one (`PlayerClip`, `textures/common/caulk`,
/// `UCX_Wall_01`); trailing digits are cut from each word (`sky1`). Whole words only:
/// `skylight` or `eclipse` ask for nothing.
#[must_use]
pub fn default_role<'a>(names: impl IntoIterator<Item = &'a str>) -> Option<Role> {
    names.into_iter().find_map(|name| {
        words(name).into_iter().find_map(|w| {
            let w = w.trim_end_matches(|c: char| c.is_ascii_digit());
            if SKY_WORDS.contains(&w) {
                Some(Role::Sky)
            } else if SKIP_WORDS.contains(&w) {
                Some(Role::Skip)
            } else if OCCLUDER_WORDS.contains(&w) {
                Some(Role::Occluder)
            } else {
                None
            }
        })
    })
}

/// `name` cut into lower-case words (see [`default_role`]).
fn words(name: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut word = String::new();
    let mut last_lower = false;
    for c in name.chars() {
        if !c.is_alphanumeric() {
            out.extend((!word.is_empty()).then(|| std::mem::take(&mut word)));
            last_lower = false;
            continue;
        }
        if c.is_uppercase() && last_lower {
            out.push(std::mem::take(&mut word));
        }
        last_lower = c.is_lowercase();
        word.extend(c.to_lowercase());
    }
    out.extend((!word.is_empty()).then_some(word));
    out
}

/// The role a glTF `extras` object declares under `"guidebake_role"`: `Ok(None)` without
/// one.
///
/// # Errors
/// A message when the value is not a string naming a role.
pub fn extras_role(extras: Option<&str>) -> Result<Option<Role>, String> {
    let Some(json) = extras else {
        return Ok(None);
    };
    let Ok(serde_json::Value::Object(map)) = serde_json::from_str::<serde_json::Value>(json) else {
        return Ok(None);
    };
    match map.get(EXTRAS_KEY) {
        None => Ok(None),
        Some(serde_json::Value::String(s)) => Role::parse(s).map(Some).ok_or_else(|| {
            format!(
                "extras \"{EXTRAS_KEY}\": \"{s}\" is not a role; the roles are {}",
                Role::names()
            )
        }),
        Some(other) => Err(format!(
            "extras \"{EXTRAS_KEY}\": {other} is not a role name; the roles are {}",
            Role::names()
        )),
    }
}

/// The glTF `extras` key of a node's, mesh's or material's role.
pub const EXTRAS_KEY: &str = "guidebake_role";

/// How many triangles, meshes and materials took each role other than `baked`, and by what.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct RoleReport {
    /// Per role other than `baked`: the role, its triangles, and the meshes and materials
    /// (names, up to [`NAMED`] of each) whose triangles have it.
    pub roles: Vec<RoleCount>,
    /// The rules that matched no triangle (a typo in a name, most likely).
    pub unmatched_rules: Vec<String>,
}

/// One line of a [`RoleReport`].
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct RoleCount {
    /// The role.
    pub role: Role,
    /// Its triangles.
    pub triangles: u64,
    /// Meshes with a triangle of this role (up to [`NAMED`]).
    pub meshes: Vec<String>,
    /// Materials with a triangle of this role (up to [`NAMED`]).
    pub materials: Vec<String>,
}

/// Names a [`RoleCount`] keeps of each kind.
pub const NAMED: usize = 8;

impl RoleReport {
    /// The report of `roles` (per triangle of `meshes` with `materials`), and of `rules`
    /// that matched nothing.
    pub(super) fn of(
        roles: &[Role],
        triangles: &[super::Triangle],
        meshes: &[Mesh],
        materials: &[Material],
        unmatched_rules: Vec<String>,
    ) -> Self {
        let mut out: Vec<RoleCount> = Vec::new();
        for (t, &role) in triangles.iter().zip(roles) {
            if role == Role::Baked {
                continue;
            }
            let at = match out.iter().position(|c| c.role == role) {
                Some(i) => i,
                None => {
                    out.push(RoleCount {
                        role,
                        triangles: 0,
                        meshes: Vec::new(),
                        materials: Vec::new(),
                    });
                    out.len() - 1
                }
            };
            let count = &mut out[at];
            count.triangles += 1;
            let named = |list: &mut Vec<String>, name: &str| {
                if list.len() < NAMED && !list.iter().any(|n| n == name) {
                    list.push(name.to_owned());
                }
            };
            named(&mut count.meshes, &meshes[t.mesh as usize].name);
            named(&mut count.materials, &materials[t.material as usize].name);
        }
        out.sort_by_key(|c| c.role.code());
        Self {
            roles: out,
            unmatched_rules,
        }
    }

    /// One line per role for the command line: `sky: 12 triangles (meshes 'shell'; materials
    /// 'sky')`.
    #[must_use]
    pub fn lines(&self) -> Vec<String> {
        let list = |names: &[String]| {
            names
                .iter()
                .map(|n| format!("'{n}'"))
                .collect::<Vec<_>>()
                .join(", ")
        };
        self.roles
            .iter()
            .map(|c| {
                format!(
                    "{}: {} triangles (meshes {}; materials {})",
                    c.role,
                    c.triangles,
                    list(&c.meshes),
                    list(&c.materials)
                )
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn globs_match_whole_names_case_insensitively() {
        assert!(glob("sky*", "skybox_01"));
        assert!(glob("*clip*", "playerclip"));
        assert!(glob("w?ll", "wall"));
        assert!(!glob("sky", "skybox"));
        assert!(!glob("*a*b", "aaac"));
        assert!(glob("*", ""));
        assert!(
            RoleRule::parse("sky=SkyBox*")
                .unwrap()
                .matches("skybox_1", "x")
        );
    }

    #[test]
    fn rules_parse_their_target_and_refuse_what_is_no_rule() {
        let r = RoleRule::parse("no_shadow=material:Leaves*").unwrap();
        assert_eq!(r.role, Role::NoShadow);
        assert_eq!(r.target, Target::Material);
        assert!(r.matches("tree", "leaves_oak"));
        assert!(
            !r.matches("leaves_oak", "bark"),
            "a material rule ignores mesh names"
        );
        assert_eq!(r.to_string(), "no-shadow=material:leaves*");
        for bad in ["sky", "skyy=shell", "sky=", "sky=mesh:"] {
            let e = RoleRule::parse(bad).unwrap_err();
            assert!(!e.is_empty(), "{bad}");
        }
        assert!(
            RoleRule::parse("skyy=shell")
                .unwrap_err()
                .contains("no-shadow")
        );
    }

    #[test]
    fn default_roles_come_from_whole_words_of_the_names() {
        let role = |n: &str| default_role([n]);
        assert_eq!(role("sky"), Some(Role::Sky));
        assert_eq!(role("textures/skies/sky1.png"), Some(Role::Sky));
        assert_eq!(role("Sky_Dome"), Some(Role::Sky));
        assert_eq!(role("PlayerClip"), Some(Role::Skip));
        assert_eq!(role("common/trigger"), Some(Role::Skip));
        assert_eq!(role("UCX_Wall_01"), Some(Role::Skip));
        assert_eq!(role("textures/common/caulk"), Some(Role::Occluder));
        for plain in ["skylight", "eclipse", "wall01", "slot324", "clipboard", ""] {
            assert_eq!(role(plain), None, "{plain}");
        }
        assert_eq!(default_role(["wall", "caulk"]), Some(Role::Occluder));
    }

    #[test]
    fn roles_say_what_they_trace_and_bake() {
        let row = |r: Role| (r.traced(), r.has_texels());
        assert_eq!(row(Role::Baked), (true, true));
        assert_eq!(row(Role::Sky), (false, false));
        assert_eq!(row(Role::Skip), (false, false));
        assert_eq!(row(Role::NoShadow), (false, true));
        assert_eq!(row(Role::Occluder), (true, false));
        for r in Role::ALL {
            assert_eq!(Role::of_code(r.code()), Some(r));
            assert_eq!(Role::parse(r.name()), Some(r));
        }
        assert_eq!(Role::of_code(5), None);
    }

    #[test]
    fn extras_declare_a_role_or_say_what_is_wrong() {
        assert_eq!(extras_role(None), Ok(None));
        assert_eq!(extras_role(Some(r#"{"other": 1}"#)), Ok(None));
        assert_eq!(
            extras_role(Some(r#"{"guidebake_role": "Sky"}"#)),
            Ok(Some(Role::Sky))
        );
        assert!(extras_role(Some(r#"{"guidebake_role": "skyy"}"#)).is_err());
        assert!(extras_role(Some(r#"{"guidebake_role": 3}"#)).is_err());
    }
}
