//! The geometry of a synthetic scene: a paved street (ground), a row of
//! buildings with brick or plaster façades, side walls, and seeded objects
//! (crates, pillars, poster boards, kiosks) at several depths, so that a
//! moving camera sees real parallax; plus articulated pedestrians (torso,
//! head, swinging arms and legs) walking back and forth across the view.
//!
//! Every face of the static world bakes its own texture (no repeated tiles),
//! lit by a fixed sun with a Lambertian factor per face (view independent).

use super::raster::{Tri, Vertex};
use super::spec::{PedestrianSpec, SceneSpec, WorldSpec};
use super::texture::{Pattern, Rgb, Style, Texture, mix64};
use nalgebra::{Rotation3, Vector3};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

type V3 = Vector3<f64>;

/// The static world and the pedestrians' models.
#[derive(Debug, Clone)]
pub struct World {
    /// Triangles of the static world.
    pub tris: Vec<Tri>,
    /// Every texture (static faces and pedestrian parts); `Tri::material` indexes it.
    pub textures: Vec<Texture>,
    /// Pedestrians, posed per frame by [`World::pedestrian_tris`].
    pub peds: Vec<Pedestrian>,
}

/// One pedestrian: its walk and the textures of its parts.
#[derive(Debug, Clone)]
pub struct Pedestrian {
    pub spec: PedestrianSpec,
    /// Texture indices: shirt, trousers, skin, hair.
    pub materials: [u32; 4],
}

fn sun() -> V3 {
    V3::new(0.45, -0.6, 0.65).normalize()
}

/// Lambert factor of a face with normal `n` (ambient 0.55 + direct 0.5).
fn light(n: &V3) -> f32 {
    (0.55 + 0.5 * n.dot(&sun()).max(0.0)) as f32
}

/// Push the two triangles of a quad with corners bottom-left, bottom-right,
/// top-right, top-left (counter-clockwise seen from the front).
fn push_quad(tris: &mut Vec<Tri>, q: [V3; 4], material: u32) {
    let n = (q[1] - q[0]).cross(&(q[3] - q[0]));
    let shade = light(&n.normalize());
    let uv = [[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]];
    let v = |i: usize| Vertex { p: q[i], uv: uv[i] };
    tris.push(Tri {
        v: [v(0), v(1), v(2)],
        material,
        shade,
    });
    tris.push(Tri {
        v: [v(0), v(2), v(3)],
        material,
        shade,
    });
}

/// The five visible faces (no bottom) of a box given its 8 corners, ordered
/// x0y0z0, x1y0z0, x1y1z0, x0y1z0 then the same four at the top.
fn box_faces(c: &[V3; 8]) -> [[V3; 4]; 5] {
    [
        [c[0], c[1], c[5], c[4]],
        [c[1], c[2], c[6], c[5]],
        [c[2], c[3], c[7], c[6]],
        [c[3], c[0], c[4], c[7]],
        [c[4], c[5], c[6], c[7]],
    ]
}

fn box_corners(lo: V3, hi: V3) -> [V3; 8] {
    [
        V3::new(lo.x, lo.y, lo.z),
        V3::new(hi.x, lo.y, lo.z),
        V3::new(hi.x, hi.y, lo.z),
        V3::new(lo.x, hi.y, lo.z),
        V3::new(lo.x, lo.y, hi.z),
        V3::new(hi.x, lo.y, hi.z),
        V3::new(hi.x, hi.y, hi.z),
        V3::new(lo.x, hi.y, hi.z),
    ]
}

const EARTH: [[Rgb; 4]; 4] = [
    [
        [0.62, 0.58, 0.52],
        [0.48, 0.46, 0.44],
        [0.70, 0.66, 0.58],
        [0.25, 0.23, 0.21],
    ],
    [
        [0.55, 0.50, 0.45],
        [0.66, 0.60, 0.50],
        [0.42, 0.40, 0.38],
        [0.22, 0.20, 0.18],
    ],
    [
        [0.60, 0.35, 0.25],
        [0.72, 0.45, 0.32],
        [0.35, 0.33, 0.30],
        [0.80, 0.78, 0.72],
    ],
    [
        [0.78, 0.74, 0.62],
        [0.60, 0.66, 0.70],
        [0.45, 0.40, 0.32],
        [0.30, 0.28, 0.30],
    ],
];
const VIVID: [Rgb; 8] = [
    [0.85, 0.15, 0.12],
    [0.10, 0.45, 0.80],
    [0.95, 0.75, 0.10],
    [0.15, 0.65, 0.30],
    [0.60, 0.20, 0.65],
    [0.95, 0.50, 0.10],
    [0.10, 0.70, 0.75],
    [0.92, 0.92, 0.90],
];

fn jitter_palette(p: [Rgb; 4], rng: &mut Pcg64, amount: f32) -> [Rgb; 4] {
    p.map(|c| c.map(|v| (v + rng.random_range(-amount..amount)).clamp(0.0, 1.0)))
}

fn vivid(rng: &mut Pcg64) -> [Rgb; 4] {
    let mut p = [[0.0; 3]; 4];
    for c in &mut p {
        *c = VIVID[rng.random_range(0..VIVID.len())];
    }
    p
}

struct Builder {
    tris: Vec<Tri>,
    textures: Vec<Texture>,
    rng: Pcg64,
    tpm: f64,
}

impl Builder {
    /// A quad with its own texture, baked at the face's metric size.
    fn face(&mut self, q: [V3; 4], pattern: Pattern, palette: [Rgb; 4]) {
        let seed = mix64(self.rng.random::<u64>());
        let style = Style {
            pattern,
            palette,
            seed,
        };
        let tex = Texture::bake(&style, (q[1] - q[0]).norm(), (q[3] - q[0]).norm(), self.tpm);
        self.textures.push(tex);
        push_quad(&mut self.tris, q, (self.textures.len() - 1) as u32);
    }

    fn solid(&mut self, corners: &[V3; 8], pattern: Pattern, palette: [Rgb; 4], faces: &[usize]) {
        let all = box_faces(corners);
        for &f in faces {
            self.face(all[f], pattern, palette);
        }
    }
}

fn seg_dist(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let l2 = dx * dx + dy * dy;
    let t = if l2 > 0.0 {
        (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p[0] - a[0] - t * dx).hypot(p[1] - a[1] - t * dy)
}

impl Builder {
    /// The ground (texture v runs from the far edge at the top to the near edge).
    fn ground(&mut self, hx: f64, y_back: f64, y_far: f64) {
        let pal = jitter_palette(EARTH[self.rng.random_range(0..2)], &mut self.rng, 0.04);
        self.face(
            [
                V3::new(-hx, y_back, 0.0),
                V3::new(hx, y_back, 0.0),
                V3::new(hx, y_far, 0.0),
                V3::new(-hx, y_far, 0.0),
            ],
            Pattern::Paving,
            pal,
        );
    }

    /// Side walls closing the street at x = ±`hx`, facing inwards.
    fn side_walls(&mut self, hx: f64, y_back: f64, y_far: f64) {
        for side in [-1.0, 1.0] {
            let x = side * hx;
            let y_near = y_back + 5.0;
            let (ya, yc) = if side < 0.0 {
                (y_far, y_near)
            } else {
                (y_near, y_far)
            };
            let pal = jitter_palette(EARTH[3], &mut self.rng, 0.08);
            self.face(
                [
                    V3::new(x, ya, 0.0),
                    V3::new(x, yc, 0.0),
                    V3::new(x, yc, 7.0),
                    V3::new(x, ya, 7.0),
                ],
                Pattern::Plaster,
                pal,
            );
        }
    }

    /// A row of buildings with staggered façades from x = −`hx` to `hx`, the
    /// front at depth `yb` or up to 1.2 m behind it.
    fn buildings(&mut self, w: &WorldSpec, hx: f64, yb: f64) {
        let mut x = -hx;
        while x < hx - 0.1 {
            let bw = self.rng.random_range(3.0..7.0f64).min(hx - x);
            let h = self
                .rng
                .random_range(w.building_height[0]..=w.building_height[1]);
            let yf = yb + self.rng.random_range(0.0..1.2);
            let brick = self.rng.random_bool(0.6);
            let pal = jitter_palette(EARTH[self.rng.random_range(0..4)], &mut self.rng, 0.06);
            // Roofs are never seen from street level; sides only between staggered façades.
            let c = box_corners(V3::new(x, yf, 0.0), V3::new(x + bw, yb + 2.5, h));
            self.solid(
                &c,
                if brick {
                    Pattern::Brick
                } else {
                    Pattern::Facade
                },
                pal,
                &[0, 1, 3],
            );
            x += bw;
        }
    }

    /// Objects at several depths in front of the buildings (depth `yb`),
    /// kept clear of the walkers, the camera path and each other.
    fn objects(&mut self, spec: &SceneSpec, hx: f64, yb: f64) {
        let w = &spec.world;
        let mut keep_out: Vec<([f64; 2], [f64; 2], f64)> = spec
            .pedestrians
            .iter()
            .map(|p| (p.start, p.end, 0.35 * p.height / 1.75 + w.clearance))
            .collect();
        let eyes = &spec.camera.eye;
        for (i, e) in eyes.iter().enumerate() {
            let n = eyes.get(i + 1).unwrap_or(e);
            keep_out.push(([e[0], e[1]], [n[0], n[1]], 1.0 + w.clearance));
        }
        let mut placed: Vec<([f64; 2], f64)> = Vec::new();
        let mut tries = 0;
        while placed.len() < w.objects as usize && tries < 200 * (w.objects as usize + 1) {
            tries += 1;
            let kind = self.rng.random_range(0..4u32);
            let (sx, sy, sz) = self.object_size(kind);
            let px = self.rng.random_range(-hx + 1.5..hx - 1.5);
            let py = self.rng.random_range(w.object_depth[0]..=w.object_depth[1]);
            let yaw = self.rng.random_range(-0.5..0.5f64);
            let r = 0.5 * sx.hypot(sy);
            if keep_out
                .iter()
                .any(|(a, c, m)| seg_dist([px, py], *a, *c) < r + m)
                || placed
                    .iter()
                    .any(|(q, rq)| (q[0] - px).hypot(q[1] - py) < r + rq + 0.2)
                || py + r > yb
            {
                continue;
            }
            placed.push(([px, py], r));
            let rot = Rotation3::from_axis_angle(&Vector3::z_axis(), yaw);
            let centre = V3::new(px, py, 0.0);
            let c = box_corners(
                V3::new(-sx / 2.0, -sy / 2.0, 0.0),
                V3::new(sx / 2.0, sy / 2.0, sz),
            )
            .map(|p| centre + rot * p);
            let (pattern, pal) = self.object_style(kind);
            self.solid(&c, pattern, pal, &[0, 1, 2, 3, 4]);
        }
    }

    /// Width, depth and height (m) of an object of `kind`: 0 a crate, 1 a
    /// pillar, 2 a board, 3 a kiosk.
    fn object_size(&mut self, kind: u32) -> (f64, f64, f64) {
        let rng = &mut self.rng;
        match kind {
            0 => {
                let s = rng.random_range(0.5..1.2);
                (
                    s * rng.random_range(0.8..1.6),
                    s,
                    s * rng.random_range(0.7..1.2),
                )
            }
            1 => {
                let s = rng.random_range(0.3..0.55);
                (s, s, rng.random_range(2.2..4.0))
            }
            2 => (rng.random_range(1.0..2.0), 0.12, rng.random_range(1.5..2.4)),
            _ => (
                rng.random_range(1.5..2.5),
                rng.random_range(1.2..2.0),
                rng.random_range(2.2..2.8),
            ),
        }
    }

    /// The pattern and palette of an object of `kind`.
    fn object_style(&mut self, kind: u32) -> (Pattern, [Rgb; 4]) {
        let rng = &mut self.rng;
        match kind {
            0 if rng.random_bool(0.5) => (Pattern::Wood, jitter_palette(EARTH[2], rng, 0.1)),
            0 => (Pattern::Checker, vivid(rng)),
            1 => (
                if rng.random_bool(0.5) {
                    Pattern::Plaster
                } else {
                    Pattern::Checker
                },
                jitter_palette(EARTH[rng.random_range(0..4)], rng, 0.1),
            ),
            _ => (Pattern::Poster, vivid(rng)),
        }
    }

    /// The pedestrians, their textures baked once (geometry is posed per frame).
    fn pedestrians(&mut self, spec: &SceneSpec) -> Vec<Pedestrian> {
        let mut peds = Vec::new();
        for p in &spec.pedestrians {
            let mut mats = [0u32; 4];
            let skin_tone = self.rng.random_range(0.35..0.95f32);
            let skin = [[skin_tone, skin_tone * 0.78, skin_tone * 0.62]; 4];
            let hair = [
                [0.12, 0.08, 0.05],
                [0.25, 0.18, 0.1],
                [0.1, 0.1, 0.1],
                [0.3, 0.25, 0.2],
            ];
            let denim = [
                [0.12, 0.18, 0.38],
                [0.2, 0.25, 0.45],
                [0.1, 0.1, 0.12],
                [0.3, 0.3, 0.35],
            ];
            let styles = [
                (Pattern::Cloth, vivid(&mut self.rng)),
                (
                    Pattern::Cloth,
                    if self.rng.random_bool(0.5) {
                        denim
                    } else {
                        vivid(&mut self.rng)
                    },
                ),
                (Pattern::Skin, skin),
                (Pattern::Skin, hair),
            ];
            for (m, (pattern, palette)) in mats.iter_mut().zip(styles) {
                let style = Style {
                    pattern,
                    palette,
                    seed: mix64(self.rng.random::<u64>()),
                };
                self.textures
                    .push(Texture::bake(&style, 0.5, 0.8, self.tpm.max(96.0)));
                *m = (self.textures.len() - 1) as u32;
            }
            peds.push(Pedestrian {
                spec: p.clone(),
                materials: mats,
            });
        }
        peds
    }
}

impl World {
    /// Build the world of `spec` (deterministic from `spec.seed`).
    pub fn build(spec: &SceneSpec) -> World {
        let w = &spec.world;
        let mut b = Builder {
            tris: Vec::new(),
            textures: Vec::new(),
            rng: Pcg64::seed_from_u64(mix64(spec.seed ^ 0x5EED_0001)),
            tpm: w.texels_per_meter,
        };
        let (hx, yb) = (w.length / 2.0, w.building_distance);
        let y_back = spec.camera.eye.iter().map(|e| e[1]).fold(0.0f64, f64::min) - 6.0;
        let y_far = yb + 2.5;
        b.ground(hx, y_back, y_far);
        b.side_walls(hx, y_back, y_far);
        b.buildings(w, hx, yb);
        b.objects(spec, hx, yb);
        let peds = b.pedestrians(spec);
        World {
            tris: b.tris,
            textures: b.textures,
            peds,
        }
    }

    /// The pedestrians' triangles at time `t` seconds.
    pub fn pedestrian_tris(&self, t: f64) -> Vec<Tri> {
        let mut tris = Vec::new();
        for p in &self.peds {
            pose_pedestrian(p, t, &mut tris);
        }
        tris
    }
}

/// Ground position and heading of a walker at time `t` (ping-pong along its segment).
pub fn walker_position(p: &PedestrianSpec, t: f64) -> ([f64; 2], f64, f64) {
    let (dx, dy) = (p.end[0] - p.start[0], p.end[1] - p.start[1]);
    let len = dx.hypot(dy);
    let d = p.offset + p.speed * t;
    let m = d.rem_euclid(2.0 * len);
    let (f, dir) = if m < len {
        (m / len, 1.0)
    } else {
        (2.0 - m / len, -1.0)
    };
    let pos = [p.start[0] + dx * f, p.start[1] + dy * f];
    let yaw = (dy * dir).atan2(dx * dir);
    (pos, yaw, d)
}

fn pose_pedestrian(p: &Pedestrian, t: f64, tris: &mut Vec<Tri>) {
    let s = p.spec.height / 1.75;
    let (pos, yaw, dist) = walker_position(&p.spec, t);
    let stride = 0.75 * s;
    let phase = dist / (2.0 * stride) * std::f64::consts::TAU;
    let swing = 0.45 * phase.sin();
    let bob = 0.03 * s * phase.cos().abs();
    let body = Rotation3::from_axis_angle(&Vector3::z_axis(), yaw);
    let base = V3::new(pos[0], pos[1], bob);
    let [shirt, trousers, skin, hair] = p.materials;
    // (lo, hi) in the part frame, pivot in the body frame, swing angle, material.
    let parts: [(V3, V3, V3, f64, u32); 7] = [
        (
            V3::new(-0.07, -0.08, -0.88),
            V3::new(0.07, 0.08, 0.0),
            V3::new(0.0, 0.1, 0.9),
            swing,
            trousers,
        ),
        (
            V3::new(-0.07, -0.08, -0.88),
            V3::new(0.07, 0.08, 0.0),
            V3::new(0.0, -0.1, 0.9),
            -swing,
            trousers,
        ),
        (
            V3::new(-0.12, -0.21, 0.0),
            V3::new(0.12, 0.21, 0.6),
            V3::new(0.0, 0.0, 0.88),
            0.0,
            shirt,
        ),
        (
            V3::new(-0.05, -0.05, -0.6),
            V3::new(0.05, 0.05, 0.0),
            V3::new(0.0, 0.27, 1.45),
            -0.8 * swing,
            shirt,
        ),
        (
            V3::new(-0.05, -0.05, -0.6),
            V3::new(0.05, 0.05, 0.0),
            V3::new(0.0, -0.27, 1.45),
            0.8 * swing,
            shirt,
        ),
        (
            V3::new(-0.1, -0.09, 0.0),
            V3::new(0.1, 0.09, 0.2),
            V3::new(0.0, 0.0, 1.5),
            0.0,
            skin,
        ),
        (
            V3::new(-0.11, -0.1, 0.0),
            V3::new(0.11, 0.1, 0.06),
            V3::new(0.0, 0.0, 1.69),
            0.0,
            hair,
        ),
    ];
    for (lo, hi, pivot, angle, mat) in parts {
        let swing_rot = Rotation3::from_axis_angle(&Vector3::y_axis(), angle);
        let c = box_corners(lo * s, hi * s).map(|q| base + body * (pivot * s + swing_rot * q));
        for f in box_faces(&c) {
            push_quad(tris, f, mat);
        }
    }
}
