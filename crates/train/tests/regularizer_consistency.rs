//! Deformation consistency end to end, as `compare` uses it: groups from a top-k at `t_ref`
//! on a ground-truth mask, then positions at test times scored against the true rigid motion.

use train::regularizer::consistency::{squared_errors, ConsistencyAccumulator, ObjectTrack};
use train::regularizer::{ObjectGroups, TopKView, NO_GAUSSIAN};

/// Yaw `a` about z and translation `(tx, 0, 0)`: a vehicle driving along x while turning.
fn pose(a: f32, tx: f32) -> [[f32; 4]; 4] {
    let (s, c) = a.sin_cos();
    [
        [c, -s, 0.0, tx],
        [s, c, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0],
        [0.0, 0.0, 0.0, 1.0],
    ]
}

fn transform(m: &[[f32; 4]; 4], p: [f32; 3]) -> [f32; 3] {
    [0, 1, 2].map(|i| m[i][0] * p[0] + m[i][1] * p[1] + m[i][2] * p[2] + m[i][3])
}

/// 6 Gaussians: 0–2 on the moving vehicle (ID 0), 3–4 on a parked one (ID 1), 5 on the ground.
/// Local (object-frame) positions; the "model" places them at time `t` either rigidly or with
/// a wobble on Gaussian 1.
fn positions(t: f32, wobble: f32) -> Vec<f32> {
    let local = [[0.1, 0.0, 0.1], [-0.1, 0.05, 0.1], [0.0, -0.05, 0.2]];
    let mut out = Vec::new();
    for (i, p) in local.iter().enumerate() {
        let mut w = transform(&pose(t, 2.0 * t), *p);
        if i == 1 {
            w[2] += wobble * t;
        }
        out.extend(w);
    }
    out.extend([0.5, 0.5, 0.0, 0.6, 0.5, 0.0, -1.0, -1.0, 0.0]);
    out
}

#[test]
fn rigid_model_scores_zero_and_wobble_scores_its_size() {
    // t_ref render: 4 pixels with k = 2; pixel 3 is ground (background in the GT mask).
    let ids = [0, 1, 2, NO_GAUSSIAN, 3, 4, 5, NO_GAUSSIAN];
    let mask = [0u8, 0, 1, 255];
    let mut groups = ObjectGroups::new();
    groups
        .build(
            TopKView {
                ids: &ids,
                stride: 2,
            },
            2,
            &mask,
            6,
        )
        .unwrap();
    let t_ref = 0.0;
    let moving: Vec<[[f32; 4]; 4]> = [0.0, 0.5, 1.0].iter().map(|&t| pose(t, 2.0 * t)).collect();
    let parked = pose(0.3, -0.5);
    for wobble in [0.0f32, 0.6] {
        let anchor = positions(t_ref, wobble);
        let mut acc = ConsistencyAccumulator::new();
        for (ti, &t) in [0.0f32, 0.5, 1.0].iter().enumerate() {
            let tracks = [
                ObjectTrack {
                    object: 0,
                    members: groups.group(0).unwrap().members,
                    pose_ref: &moving[0],
                    pose_t: &moving[ti],
                },
                ObjectTrack {
                    object: 1,
                    members: groups.group(1).unwrap().members,
                    pose_ref: &parked,
                    pose_t: &parked,
                },
            ];
            acc.add_time(t, &tracks, &anchor, &positions(t, wobble))
                .unwrap();
        }
        let r = acc.report().unwrap();
        if wobble == 0.0 {
            assert!(r.rms < 1e-5, "{r:?}");
            continue;
        }
        // Wobble 0.6·t on one of 5 vehicle Gaussians: e(t) = 0.6·t/√5; mean over t ∈ {0, .5, 1}.
        let expect = (0.0 + 0.3 + 0.6) / 5f64.sqrt() / 3.0;
        assert!((r.rms - expect).abs() < 1e-5, "{} vs {expect}", r.rms);
        assert_eq!(r.per_time.len(), 3);
        assert!(r.per_object.iter().find(|o| o.object == 1).unwrap().rms < 1e-5);
    }
    // The parked vehicle's track at the last time, checked directly: zero error.
    let track = ObjectTrack {
        object: 1,
        members: groups.group(1).unwrap().members,
        pose_ref: &parked,
        pose_t: &parked,
    };
    let e = squared_errors(&track, &positions(0.0, 0.0), &positions(1.0, 0.0)).unwrap();
    assert_eq!(e.count, 2);
    assert!(e.sum < 1e-10 && e.sum_if_still < 1e-10);
}
