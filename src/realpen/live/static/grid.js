// A feel that follows the pen: the weights of a profile's tactile patterns at several
// (speed, force) points, the same numbers as realpen.tactile.grid.VibrationGrid (Python).
// Tests evaluate VibrationGrid.gains in the page and compare it with Python's.
//
// The server sends the points, the Delaunay triangles it computed over them (the page never
// triangulates) and the scale of each axis (its range over the points: each axis is divided by
// it before anything is measured, so mm/s and N weigh alike). At (speed, force):
//   - at a grid point (scaled distance at most 1e-12): that point, weight 1;
//   - inside a triangle: its barycentric coordinates;
//   - outside the hull: the nearest point of the hull's edges (scaled axes), weighted along
//     that edge;
//   - points on one line (no triangles): linear interpolation along the line (its principal
//     direction), clamped to its ends.
// Weights below 1e-12 are rounding: they become 0 and the rest sum to 1 again.
// Mixing (audio.js): every point's loop plays in sync, point i's with gain sqrt(w_i) (an
// equal-power crossfade of uncorrelated patterns); force = pressure (0-1) × full_pressure_force_n.

const INSIDE = -1e-12; // a barycentric coordinate this far below 0 still counts as inside
const SAME = 1e-12; // scaled distance under which a query is at a grid point
const TINY = 1e-12; // weights below this are rounding

export class VibrationGrid {
  /** json: the `grid` of a profile in GET /api/profiles: points [{speed_mm_s, force_n, url}],
   *  triangles [[i, j, k]], scale [mm/s, N], full_pressure_force_n, reference. */
  constructor(json) {
    this.count = json.points.length;
    this.reference = json.reference;
    this.fullPressureForce = json.full_pressure_force_n;
    [this.sx, this.sy] = json.scale;
    this.xy = json.points.map((p) => [p.speed_mm_s / this.sx, p.force_n / this.sy]);
    this.triangles = json.triangles;
    this.hull = this.triangles.length ? hullEdges(this.triangles) : null;
    this.line = this.triangles.length || this.count < 2 ? null : lineOrder(this.xy);
  }

  /** Force in N for a page pressure 0-1. */
  forceOf(pressure) {
    return pressure * this.fullPressureForce;
  }

  /** { indices, weights } at (speed mm/s, force N): the points that mix, weights summing to 1. */
  weights(speed, force) {
    if (this.count === 1) return { indices: [0], weights: [1] };
    const q = [speed / this.sx, force / this.sy];
    const at = this.nearestPoint(q);
    if (at.d <= SAME * SAME) return { indices: [at.index], weights: [1] };
    if (this.line) return this.alongLine(q);
    return this.barycentric(q) || this.onHull(q);
  }

  /** The gain of every point's loop at (speed, force): sqrt of its weight, 0 for the others. */
  gains(speed, force) {
    const out = new Array(this.count).fill(0);
    const { indices, weights } = this.weights(speed, force);
    indices.forEach((index, k) => { out[index] = Math.sqrt(weights[k]); });
    return out;
  }

  nearestPoint(q) {
    let best = { index: -1, d: Infinity };
    this.xy.forEach(([x, y], index) => {
      const d = (x - q[0]) ** 2 + (y - q[1]) ** 2;
      if (d < best.d) best = { index, d };
    });
    return best;
  }

  /** The weights in the triangle that holds q, or null when none does. */
  barycentric(q) {
    for (const triangle of this.triangles) {
      const [a, b, c] = triangle.map((i) => this.xy[i]);
      const det = (b[1] - c[1]) * (a[0] - c[0]) + (c[0] - b[0]) * (a[1] - c[1]);
      const w0 = ((b[1] - c[1]) * (q[0] - c[0]) + (c[0] - b[0]) * (q[1] - c[1])) / det;
      const w1 = ((c[1] - a[1]) * (q[0] - c[0]) + (a[0] - c[0]) * (q[1] - c[1])) / det;
      const w = [w0, w1, 1 - w0 - w1];
      if (Math.min(...w) >= INSIDE) return tidy(triangle, w);
    }
    return null;
  }

  /** Outside the hull: the weights at the nearest point of its edges (along that edge). */
  onHull(q) {
    let best = null;
    for (const [i, j] of this.hull) {
      const a = this.xy[i];
      const b = this.xy[j];
      const dx = b[0] - a[0];
      const dy = b[1] - a[1];
      const t = Math.min(Math.max(((q[0] - a[0]) * dx + (q[1] - a[1]) * dy)
        / (dx * dx + dy * dy), 0), 1);
      const d = (a[0] + t * dx - q[0]) ** 2 + (a[1] + t * dy - q[1]) ** 2;
      if (!best || d < best.d) best = { i, j, t, d };
    }
    return tidy([best.i, best.j], [1 - best.t, best.t]);
  }

  alongLine(q) {
    const { origin, direction, order, t } = this.line;
    const s = Math.min(Math.max((q[0] - origin[0]) * direction[0]
      + (q[1] - origin[1]) * direction[1], t[0]), t[t.length - 1]);
    let k = 0;
    while (k < t.length - 2 && s > t[k + 1]) k += 1;
    const u = (s - t[k]) / (t[k + 1] - t[k]);
    return tidy([order[k], order[k + 1]], [1 - u, u]);
  }
}

/** Weights below TINY dropped, the rest summing to 1; only the points that weigh anything. */
function tidy(indices, w) {
  const clipped = w.map((x) => (x < TINY ? 0 : x));
  const total = clipped.reduce((a, b) => a + b, 0);
  const kept = { indices: [], weights: [] };
  clipped.forEach((x, k) => {
    if (x > 0) { kept.indices.push(indices[k]); kept.weights.push(x / total); }
  });
  return kept;
}

/** The hull's edges: those of exactly one triangle. */
function hullEdges(triangles) {
  const seen = new Map();
  for (const [a, b, c] of triangles) {
    for (const [i, j] of [[a, b], [b, c], [c, a]]) {
      const key = i < j ? `${i},${j}` : `${j},${i}`;
      seen.set(key, (seen.get(key) || 0) + 1);
    }
  }
  return [...seen].filter(([, n]) => n === 1).map(([key]) => key.split(',').map(Number));
}

/** Points on one line: its origin (their mean), its direction (their principal axis) and
 *  the points in order along it. */
function lineOrder(xy) {
  const n = xy.length;
  const origin = [xy.reduce((s, p) => s + p[0], 0) / n, xy.reduce((s, p) => s + p[1], 0) / n];
  let sxx = 0;
  let sxy = 0;
  let syy = 0;
  for (const [x, y] of xy) {
    sxx += (x - origin[0]) ** 2;
    sxy += (x - origin[0]) * (y - origin[1]);
    syy += (y - origin[1]) ** 2;
  }
  const angle = 0.5 * Math.atan2(2 * sxy, sxx - syy); // the covariance's principal eigenvector
  const direction = [Math.cos(angle), Math.sin(angle)];
  const along = xy.map(([x, y]) => (x - origin[0]) * direction[0] + (y - origin[1]) * direction[1]);
  const order = along.map((_, i) => i).sort((i, j) => along[i] - along[j] || i - j);
  return { origin, direction, order, t: order.map((i) => along[i]) };
}
