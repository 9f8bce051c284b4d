//! Plane geometry in metres: points, wall segments, circles, rays and polygons. Everything the
//! motion and sensor models ask of the arena goes through these few functions.

/// A point or a vector in the world frame, metres.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Vec2 {
    /// x, metres.
    pub x: f64,
    /// y, metres.
    pub y: f64,
}

impl Vec2 {
    /// The point (x, y).
    pub const fn new(x: f64, y: f64) -> Vec2 {
        Vec2 { x, y }
    }

    /// The unit vector at `angle` radians from +x, counter-clockwise.
    pub fn from_angle(angle: f64) -> Vec2 {
        Vec2::new(angle.cos(), angle.sin())
    }

    /// Sum.
    pub fn plus(self, o: Vec2) -> Vec2 {
        Vec2::new(self.x + o.x, self.y + o.y)
    }

    /// Difference `self − o`.
    pub fn minus(self, o: Vec2) -> Vec2 {
        Vec2::new(self.x - o.x, self.y - o.y)
    }

    /// Scaled by `k`.
    pub fn scale(self, k: f64) -> Vec2 {
        Vec2::new(self.x * k, self.y * k)
    }

    /// Dot product.
    pub fn dot(self, o: Vec2) -> f64 {
        self.x * o.x + self.y * o.y
    }

    /// The z component of the cross product.
    pub fn cross(self, o: Vec2) -> f64 {
        self.x * o.y - self.y * o.x
    }

    /// Length.
    pub fn length(self) -> f64 {
        self.dot(self).sqrt()
    }

    /// This vector (a point in a body frame) rotated by `angle` radians and moved by `origin`.
    pub fn to_world(self, origin: Vec2, angle: f64) -> Vec2 {
        let (s, c) = angle.sin_cos();
        Vec2::new(
            origin.x + c * self.x - s * self.y,
            origin.y + s * self.x + c * self.y,
        )
    }
}

/// A straight piece of wall from `a` to `b`, with the fraction of light it reflects.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    /// One end.
    pub a: Vec2,
    /// The other end.
    pub b: Vec2,
    /// Reflectance relative to the ring's reference surface (1.0; see `ring`).
    pub reflectance: f64,
}

impl Segment {
    /// The point of the segment nearest to `p`.
    pub fn nearest_point(&self, p: Vec2) -> Vec2 {
        let ab = self.b.minus(self.a);
        let len2 = ab.dot(ab);
        if len2 == 0.0 {
            return self.a;
        }
        let t = (p.minus(self.a).dot(ab) / len2).clamp(0.0, 1.0);
        self.a.plus(ab.scale(t))
    }

    /// Distance from `p` to the segment.
    pub fn distance_to(&self, p: Vec2) -> f64 {
        p.minus(self.nearest_point(p)).length()
    }

    /// Where a ray from `origin` along the unit vector `direction` first meets the segment:
    /// the distance along the ray, or `None` if it misses (a ray parallel to the segment misses).
    pub fn ray_hit(&self, origin: Vec2, direction: Vec2) -> Option<f64> {
        let edge = self.b.minus(self.a);
        let denominator = direction.cross(edge);
        if denominator.abs() < 1e-15 {
            return None;
        }
        let to_a = self.a.minus(origin);
        let t = to_a.cross(edge) / denominator;
        let u = to_a.cross(direction) / denominator;
        (t >= 0.0 && (0.0..=1.0).contains(&u)).then_some(t)
    }
}

/// A round obstacle (a can, a post).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Circle {
    /// Centre.
    pub centre: Vec2,
    /// Radius, metres.
    pub radius: f64,
    /// Reflectance relative to the ring's reference surface.
    pub reflectance: f64,
}

impl Circle {
    /// Distance from `p` to the circle's edge (negative inside).
    pub fn distance_to(&self, p: Vec2) -> f64 {
        p.minus(self.centre).length() - self.radius
    }

    /// Where a ray from `origin` along the unit vector `direction` first meets the circle's edge
    /// from outside; `None` if it misses or starts inside.
    pub fn ray_hit(&self, origin: Vec2, direction: Vec2) -> Option<f64> {
        let to_origin = origin.minus(self.centre);
        let b = to_origin.dot(direction);
        let c = to_origin.dot(to_origin) - self.radius * self.radius;
        if c < 0.0 {
            return None;
        }
        let discriminant = b * b - c;
        if discriminant < 0.0 {
            return None;
        }
        let t = -b - discriminant.sqrt();
        (t >= 0.0).then_some(t)
    }
}

/// Whether `p` lies inside the polygon `points` (even-odd rule; the polygon closes itself).
pub fn inside_polygon(points: &[Vec2], p: Vec2) -> bool {
    let mut inside = false;
    let mut j = points.len().wrapping_sub(1);
    for (i, pi) in points.iter().enumerate() {
        let Some(pj) = points.get(j) else {
            break;
        };
        if (pi.y > p.y) != (pj.y > p.y) {
            let x = pj.x + (p.y - pj.y) * (pi.x - pj.x) / (pi.y - pj.y);
            if p.x < x {
                inside = !inside;
            }
        }
        j = i;
    }
    inside
}

#[cfg(test)]
mod tests {
    use super::*;

    fn wall(ax: f64, ay: f64, bx: f64, by: f64) -> Segment {
        Segment {
            a: Vec2::new(ax, ay),
            b: Vec2::new(bx, by),
            reflectance: 1.0,
        }
    }

    #[test]
    fn a_ray_meets_a_wall_at_the_worked_out_distance() {
        // A wall along x = 1 from y = −1 to 1; a ray from the origin at 30° meets it at
        // 1 / cos 30° = 1.1547 m.
        let w = wall(1.0, -1.0, 1.0, 1.0);
        let t = w
            .ray_hit(Vec2::default(), Vec2::from_angle(30f64.to_radians()))
            .unwrap();
        assert!((t - 1.154_700_5).abs() < 1e-6, "{t}");
        // Beyond the end (tan 50° > 1), behind, and parallel: no hit.
        assert_eq!(
            w.ray_hit(Vec2::default(), Vec2::from_angle(50f64.to_radians())),
            None
        );
        assert_eq!(w.ray_hit(Vec2::default(), Vec2::new(-1.0, 0.0)), None);
        assert_eq!(w.ray_hit(Vec2::default(), Vec2::new(0.0, 1.0)), None);
    }

    #[test]
    fn distances_to_a_segment_and_a_circle() {
        let w = wall(0.0, 0.0, 2.0, 0.0);
        assert!((w.distance_to(Vec2::new(1.0, 0.3)) - 0.3).abs() < 1e-12);
        // Past the end: to the end point, 3-4-5.
        assert!((w.distance_to(Vec2::new(5.0, 4.0)) - 5.0).abs() < 1e-12);
        let c = Circle {
            centre: Vec2::new(1.0, 1.0),
            radius: 0.25,
            reflectance: 1.0,
        };
        assert!((c.distance_to(Vec2::new(1.0, 0.0)) - 0.75).abs() < 1e-12);
        let t = c.ray_hit(Vec2::new(0.0, 1.0), Vec2::new(1.0, 0.0)).unwrap();
        assert!((t - 0.75).abs() < 1e-12);
        assert_eq!(c.ray_hit(Vec2::new(0.0, 1.0), Vec2::new(-1.0, 0.0)), None);
    }

    #[test]
    fn points_inside_and_outside_a_polygon() {
        let square = [
            Vec2::new(0.0, 0.0),
            Vec2::new(1.0, 0.0),
            Vec2::new(1.0, 1.0),
            Vec2::new(0.0, 1.0),
        ];
        assert!(inside_polygon(&square, Vec2::new(0.5, 0.5)));
        assert!(!inside_polygon(&square, Vec2::new(1.5, 0.5)));
        assert!(!inside_polygon(&[], Vec2::new(0.5, 0.5)));
    }

    #[test]
    fn body_points_rotate_into_the_world() {
        let p = Vec2::new(0.05, 0.0).to_world(Vec2::new(1.0, 2.0), 90f64.to_radians());
        assert!((p.x - 1.0).abs() < 1e-12 && (p.y - 2.05).abs() < 1e-12);
    }
}
