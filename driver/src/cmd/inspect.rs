//! `guidebake inspect FILE.texels [--texel ID ...] [--json]`: print a texel file's header
//! and counts (after full validation), and dump chosen texels.

use std::path::PathBuf;

use crate::texels::{SEEN_BACK, SEEN_FRONT, TexelFile, TexelRecord, TriangleRecord};

/// Arguments of `guidebake inspect`.
#[derive(Debug, clap::Args)]
pub struct InspectArgs {
    /// The texel file.
    pub file: PathBuf,
    /// Texel ids to dump (repeatable).
    #[arg(long = "texel")]
    pub texels: Vec<u64>,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

#[derive(serde::Serialize)]
struct TexelJson {
    id: u64,
    position: [f32; 3],
    normal: [f32; 3],
    dpdu: [f32; 3],
    dpdv: [f32; 3],
    page: u32,
    pixel: [u16; 2],
    triangle: u32,
    flags: u32,
}

impl TexelJson {
    fn new(id: u64, t: &TexelRecord) -> Self {
        Self {
            id,
            position: t.position,
            normal: t.normal,
            dpdu: t.dpdu,
            dpdv: t.dpdv,
            page: t.page,
            pixel: t.pixel,
            triangle: t.triangle,
            flags: t.flags,
        }
    }
}

/// Runs `guidebake inspect`.
///
/// # Errors
/// The file fails validation, or a requested texel id is out of range.
pub fn run(args: &InspectArgs) -> Result<(), super::CmdError> {
    let f = TexelFile::open(&args.file)?;
    let h = f.header();
    let all = f.texels();
    let mut dump = Vec::with_capacity(args.texels.len());
    for &id in &args.texels {
        let t = usize::try_from(id)
            .ok()
            .and_then(|i| all.get(i))
            .ok_or_else(|| {
                format!(
                    "{}: texel {id} is out of range (the file has {} texels)",
                    args.file.display(),
                    all.len()
                )
            })?;
        dump.push(TexelJson::new(id, t));
    }
    let partial = all
        .iter()
        .filter(|t| t.flags & crate::texels::FLAG_PARTIAL != 0)
        .count();
    let sides = TriangleCounts::of(f.triangles());
    if args.json {
        let v = serde_json::json!({
            "file": args.file,
            "version": h.version,
            "file_size": h.file_size,
            "texel_count": h.texel_count,
            "partial_texels": partial,
            "tile_count": h.tile_count,
            "tile_size": h.tile_size,
            "pages": f.pages().iter().map(|p| [p.width, p.height]).collect::<Vec<_>>(),
            "triangle_count": h.triangle_count,
            "lightmapped_triangles": sides.lightmapped,
            "triangles_seen_from_front": sides.front,
            "triangles_seen_from_back": sides.back,
            "triangles_seen_from_both_sides": sides.both,
            "triangle_roles": sides.roles.iter().copied().collect::<std::collections::BTreeMap<_, _>>(),
            "texels_per_unit": h.texels_per_unit,
            "bounds": [h.bounds_min, h.bounds_max],
            "identity": format!("{:016x}", f.identity()),
            "geometry": format!("{:016x}", h.geometry),
            "lighting": format!("{:016x}", h.lighting),
            "texels": dump,
        });
        println!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(());
    }
    println!(
        "{}: texel file version {}, {} bytes",
        args.file.display(),
        h.version,
        h.file_size
    );
    println!("  texels: {} ({partial} partial)", h.texel_count);
    println!(
        "  tiles:  {} (up to {}x{})",
        h.tile_count, h.tile_size, h.tile_size
    );
    let pages: Vec<String> = f
        .pages()
        .iter()
        .map(|p| format!("{}x{}", p.width, p.height))
        .collect();
    println!("  pages:  {} [{}]", pages.len(), pages.join(", "));
    println!(
        "  triangles: {} ({} with lightmap UVs; seen from the front {}, the back {}, both sides {})",
        h.triangle_count, sides.lightmapped, sides.front, sides.back, sides.both
    );
    if !sides.roles.is_empty() {
        let roles: Vec<String> = sides
            .roles
            .iter()
            .map(|(r, n)| format!("{r} {n}"))
            .collect();
        println!("  roles (docs/levels.md): {}", roles.join(", "));
    }
    println!("  bounds: {:?} .. {:?}", h.bounds_min, h.bounds_max);
    println!(
        "  identity {:016x}; the scene's geometry {:016x}, its lights {:016x} (0: not recorded)",
        f.identity(),
        h.geometry,
        h.lighting
    );
    println!("  texels per unit: {}", h.texels_per_unit);
    for t in &dump {
        println!(
            "  texel {}: position {:?} normal {:?} page {} pixel {:?} triangle {} flags {:#x}",
            t.id, t.position, t.normal, t.page, t.pixel, t.triangle, t.flags
        );
    }
    Ok(())
}

/// How many triangles of the table have lightmap UVs, and from which sides they are seen.
struct TriangleCounts {
    lightmapped: usize,
    front: usize,
    back: usize,
    both: usize,
    /// Per role but `baked` (`scene::roles`), its name and triangles, where any.
    roles: Vec<(&'static str, usize)>,
}

impl TriangleCounts {
    fn of(triangles: &[TriangleRecord]) -> Self {
        let seen = |flags: u32| {
            triangles
                .iter()
                .filter(|t| t.flags & (SEEN_FRONT | SEEN_BACK) == flags)
                .count()
        };
        Self {
            lightmapped: triangles.iter().filter(|t| t.pixel_uv().is_some()).count(),
            front: seen(SEEN_FRONT),
            back: seen(SEEN_BACK),
            both: seen(SEEN_FRONT | SEEN_BACK),
            roles: crate::scene::Role::ALL[1..]
                .iter()
                .map(|&r| (r.name(), triangles.iter().filter(|t| t.role() == r).count()))
                .filter(|&(_, n)| n > 0)
                .collect(),
        }
    }
}
