//! Retargeting real CMU clips onto the sample body: feet on the floor in stance, body upright.

use crate::common::*;
use garmentbake::io::gltf_body::read_body;
use garmentbake::motion::load_clip;

#[test]
fn retargeted_walk_keeps_stance_feet_on_the_floor_and_the_body_upright() {
    let body = read_body(&sample("body.glb")).unwrap();
    let sk = &body.skeleton;
    let anim = sample_clip(&body, "131_01", None);
    let j = |n: &str| sk.joint_index(n).unwrap();
    // The lowest foot vertex of either foot on frames where a foot stands (the ground is put
    // there), and each foot's own on its stance frames: a foot planted beside the grounded one
    // floats where our legs' proportions differ from the performer's (131_01: up to 40 mm).
    let feet = [
        j("LeftFoot"),
        j("LeftToeBase"),
        j("RightFoot"),
        j("RightToeBase"),
    ];
    let lowest = lowest_vertex(&body, &anim, &feet);
    let (mut lowest_errors, mut stance_errors) = (Vec::new(), Vec::new());
    let mut standing = vec![false; anim.frame_count()];
    for side in ["Left", "Right"] {
        let foot = j(&format!("{side}Foot"));
        let low = lowest_vertex(&body, &anim, &[foot, j(&format!("{side}ToeBase"))]);
        let pos: Vec<_> = (0..anim.frame_count())
            .map(|f| anim.joint_positions(sk, f)[foot])
            .collect();
        // Stance: the foot joint moves slower than 0.2 m/s horizontally.
        for f in 1..anim.frame_count() {
            let v = (pos[f] - pos[f - 1]).xz().norm() * anim.fps;
            if v < 0.2 {
                stance_errors.push(low[f].abs());
                standing[f] = true;
            }
        }
    }
    for (f, _) in standing.iter().enumerate().filter(|(_, &s)| s) {
        lowest_errors.push(lowest[f].abs());
    }
    let p = |v: &mut Vec<f32>, q: usize| {
        v.sort_by(f32::total_cmp);
        v[v.len() * q / 100]
    };
    let (lowest95, lowest50) = (p(&mut lowest_errors, 95), p(&mut lowest_errors, 50));
    let (p95, median) = (p(&mut stance_errors, 95), p(&mut stance_errors, 50));
    eprintln!(
        "stance frames: {} (of a foot: {}); |lowest foot vertex height| median {:.1} mm, p95 {:.1} mm; \
         each foot on its own stance frames: median {:.1} mm, p95 {:.1} mm",
        lowest_errors.len(),
        stance_errors.len(),
        lowest50 * 1e3,
        lowest95 * 1e3,
        median * 1e3,
        p95 * 1e3
    );
    // Measured 988 of the 2 × 993 foot steps (docs/foundation.md); a tenth fewer fails.
    assert!(stance_errors.len() >= 890, "too few stance frames");
    assert!(
        lowest95 < 0.03,
        "95 % of standing frames' lowest foot vertex within 3 cm of the floor, got {:.1} mm",
        lowest95 * 1e3
    );
    // Measured 39.4 mm (the floating foot beside the grounded one).
    assert!(
        p95 < 0.06,
        "95 % of each foot's stance frames within 6 cm of the floor, got {:.1} mm",
        p95 * 1e3
    );

    // Upright: the hips→neck direction stays near vertical for most of the clip.
    let tilts: Vec<f32> = (0..anim.frame_count())
        .map(|f| {
            let p = anim.joint_positions(sk, f);
            let up = (p[j("Neck")] - p[j("Hips")]).normalize();
            up.y.clamp(-1.0, 1.0).acos().to_degrees()
        })
        .collect();
    let mut sorted = tilts.clone();
    sorted.sort_by(f32::total_cmp);
    eprintln!(
        "spine tilt: median {:.1}°, p90 {:.1}°",
        sorted[sorted.len() / 2],
        sorted[sorted.len() * 9 / 10]
    );
    assert!(
        sorted[sorted.len() / 2] < 15.0,
        "median spine tilt {:.1}°",
        sorted[sorted.len() / 2]
    );
}

#[test]
fn both_cmu_namings_are_recognised_without_a_map() {
    let body = read_body(&sample("body.glb")).unwrap();
    let mb = load_clip(
        &sample("motions/01_01.bvh"),
        &Default::default(),
        &body,
        None,
    )
    .unwrap();
    let max = load_clip(
        &sample("motions/131_02.bvh"),
        &Default::default(),
        &body,
        None,
    )
    .unwrap();
    assert_eq!(mb.map_name, "cmu_mb");
    assert_eq!(max.map_name, "cmu_3dsmax");
    assert_eq!(
        max.animation.fps, 120.0,
        "CMU's .0083333 s frame time is 120 Hz"
    );
    // CMU units are about 0.0548 m judged by leg length; our hip-height scale lands near it.
    assert!((0.045..0.065).contains(&max.scale), "{}", max.scale);
}

/// `scripts/augment_bvh.py` on the shipped 131_01 with `args`, written to `dir/out`.
fn augment_131_01(dir: &std::path::Path, out: &str, args: &[&str]) -> std::path::PathBuf {
    let path = dir.join(out);
    run_ok(
        std::process::Command::new("python3")
            .arg(root().join("scripts/augment_bvh.py"))
            .arg(sample("motions/131_01.bvh"))
            .arg(&path)
            .args(args),
    );
    path
}

/// `scripts/augment_bvh.py --mirror` (new training motion for the dynamic model): the mirrored
/// clip, retargeted onto the body, is the original's mirror image (x → −x): every hand, forearm,
/// knee and foot is where the other side's was. `--speed 1.25` plays the same poses sooner.
#[test]
fn a_mirrored_clip_is_the_mirror_image_and_a_faster_one_the_same_poses_sooner() {
    let dir = out_dir("augment_bvh");
    let augment = |out: &str, args: &[&str]| augment_131_01(&dir, out, args);
    let (mirrored, faster) = (
        augment("mirrored.bvh", &["--mirror"]),
        augment("faster.bvh", &["--speed", "1.25"]),
    );
    let body = read_body(&sample("body.glb")).unwrap();
    let sk = &body.skeleton;
    let load = |p: &std::path::Path| {
        load_clip(p, &Default::default(), &body, Some(30.0))
            .unwrap()
            .animation
    };
    let (a, m, s) = (
        load(&sample("motions/131_01.bvh")),
        load(&mirrored),
        load(&faster),
    );
    let j = |n: &str| sk.joint_index(n).unwrap();
    let pairs = [
        ("LeftHand", "RightHand"),
        ("LeftForeArm", "RightForeArm"),
        ("LeftLeg", "RightLeg"),
        ("LeftFoot", "RightFoot"),
    ];
    let (mut worst, mut moved) = (0.0f32, 0.0f32);
    for f in (0..a.frame_count()).step_by(5) {
        let (p, q) = (a.joint_positions(sk, f), m.joint_positions(sk, f));
        for (l, r) in pairs.iter().flat_map(|&(l, r)| [(l, r), (r, l)]) {
            let (x, y) = (p[j(l)], q[j(r)]);
            worst =
                worst.max(((x.x + y.x).powi(2) + (x.y - y.y).powi(2) + (x.z - y.z).powi(2)).sqrt());
            moved = moved.max((x - y).norm());
        }
    }
    eprintln!(
        "mirrored: worst {:.1} mm from the mirror image ({:.0} mm from the original)",
        worst * 1e3,
        moved * 1e3
    );
    assert!(worst < 0.02, "{:.1} mm", worst * 1e3);
    assert!(
        moved > 0.2,
        "the mirrored clip must differ from the original"
    );
    // 1.25× as fast: frame 4k of the faster clip is frame 5k of the original (30 fps); the hand
    // is compared relative to the hips, since grounding smooths the root over 0.1 s windows,
    // which cover other instants of a faster take.
    let expected = a.frame_count() as f32 / 1.25;
    assert!(
        (s.frame_count() as f32 - expected).abs() <= 1.0,
        "{} frames",
        s.frame_count()
    );
    for k in (0..s.frame_count() / 4).step_by(3) {
        let (p, q) = (a.joint_positions(sk, 5 * k), s.joint_positions(sk, 4 * k));
        let hand = |x: &[nalgebra::Vector3<f32>]| x[j("LeftHand")] - x[j("Hips")];
        let off = (hand(&p) - hand(&q)).norm();
        assert!(off < 1e-3, "frame {k}: {:.2} mm", off * 1e3);
    }
}

/// `scripts/augment_bvh.py --reverse` plays the same poses backwards; `--sway SEED` moves the legs
/// away from the capture smoothly and outwards only (the knees end up further apart, never
/// through each other), and the same seed gives the same clip.
#[test]
fn a_reversed_clip_plays_backwards_and_a_swayed_one_spreads_the_legs_smoothly() {
    let dir = out_dir("augment_bvh_sway");
    let augment = |out: &str, args: &[&str]| augment_131_01(&dir, out, args);
    let reversed = augment("reversed.bvh", &["--reverse"]);
    let swayed = augment("swayed.bvh", &["--sway", "7"]);
    let again = augment("swayed_again.bvh", &["--sway", "7"]);
    assert_eq!(
        std::fs::read(&swayed).unwrap(),
        std::fs::read(&again).unwrap(),
        "one seed, one clip"
    );
    let body = read_body(&sample("body.glb")).unwrap();
    let sk = &body.skeleton;
    let load = |p: &std::path::Path| {
        load_clip(p, &Default::default(), &body, Some(30.0))
            .unwrap()
            .animation
    };
    let (a, w) = (load(&sample("motions/131_01.bvh")), load(&swayed));
    let j = |n: &str| sk.joint_index(n).unwrap();
    // At the capture's own rate (120 Hz), so frame for frame.
    let native = |p: &std::path::Path| {
        load_clip(p, &Default::default(), &body, None)
            .unwrap()
            .animation
    };
    let (a120, r) = (native(&sample("motions/131_01.bvh")), native(&reversed));
    let n = a120.frame_count();
    assert_eq!(r.frame_count(), n);
    for f in (0..n).step_by(7) {
        let (p, q) = (
            a120.joint_positions(sk, f),
            r.joint_positions(sk, n - 1 - f),
        );
        let hand = |x: &[nalgebra::Vector3<f32>]| x[j("LeftHand")] - x[j("Hips")];
        let off = (hand(&p) - hand(&q)).norm();
        assert!(off < 1e-3, "frame {f}: {:.2} mm", off * 1e3);
    }
    // Knee to knee distance, and the largest step a knee takes between frames (relative to the
    // hips), in the capture and the swayed clip.
    let knees = |c: &garmentbake::rig::SkelAnimation| {
        let (mut spread, mut step) = (Vec::new(), 0.0f32);
        let mut last: Option<nalgebra::Vector3<f32>> = None;
        for f in 0..c.frame_count() {
            let p = c.joint_positions(sk, f);
            spread.push((p[j("LeftLeg")] - p[j("RightLeg")]).norm());
            let knee = p[j("LeftLeg")] - p[j("Hips")];
            if let Some(l) = last {
                step = step.max((knee - l).norm());
            }
            last = Some(knee);
        }
        (spread, step)
    };
    let ((sa, step_a), (sw, step_w)) = (knees(&a), knees(&w));
    let mean = |v: &[f32]| v.iter().sum::<f32>() / v.len() as f32;
    let closest = |v: &[f32]| v.iter().copied().fold(f32::INFINITY, f32::min);
    eprintln!(
        "knees apart: capture {:.0} mm (closest {:.0}), swayed {:.0} mm (closest {:.0}); largest knee step {:.1} → {:.1} mm",
        mean(&sa) * 1e3,
        closest(&sa) * 1e3,
        mean(&sw) * 1e3,
        closest(&sw) * 1e3,
        step_a * 1e3,
        step_w * 1e3
    );
    assert!(
        mean(&sw) > mean(&sa) + 0.02,
        "the sway must spread the legs"
    );
    assert!(
        closest(&sw) > closest(&sa) - 0.02,
        "the knees must not come closer than captured"
    );
    assert!(step_w < step_a * 1.5, "the sway must be smooth");
}
