// The ink on the writing surface: a canvas at device resolution, line widths in real mm.
//
// Strokes are kept (CSS px, pressure) so the ink survives a resize or a rotation of the tablet.
// Hidden ink draws nothing and keeps nothing: in the method's first study the writer could not
// see the ink, so only the feel of the pen mattered.

const STYLES = {
  pencil: { color: '#4b4d52', widthMm: 0.55, pressureShare: 0.7 },
  ballpoint: { color: '#1c3a94', widthMm: 0.45, pressureShare: 0.25 },
  marker: { color: '#17181c', widthMm: 1.9, pressureShare: 0.15 },
  other: { color: '#2b2d33', widthMm: 0.6, pressureShare: 0.5 },
};

/** The ink style of a profile: by name, else by its tool ("pencil (4B)", "marker", …). */
export function inkStyle(profile) {
  if (!profile) return STYLES.other;
  if (STYLES[profile.name]) return STYLES[profile.name];
  const tool = `${profile.tool || ''}`.toLowerCase();
  for (const key of ['pencil', 'ballpoint', 'marker']) if (tool.includes(key)) return STYLES[key];
  return STYLES.other;
}

export class Ink {
  constructor(canvas) {
    this.canvas = canvas;
    this.g = canvas.getContext('2d');
    this.strokes = [];
    this.current = null;
    this.resize();
    new ResizeObserver(() => this.resize()).observe(canvas);
  }

  resize() {
    const ratio = window.devicePixelRatio || 1;
    const { width, height } = this.canvas.getBoundingClientRect();
    const w = Math.max(1, Math.round(width * ratio));
    const h = Math.max(1, Math.round(height * ratio));
    if (this.canvas.width === w && this.canvas.height === h) return;
    this.canvas.width = w;
    this.canvas.height = h;
    this.g.setTransform(ratio, 0, 0, ratio, 0, 0);
    this.g.lineCap = 'round';
    this.g.lineJoin = 'round';
    for (const stroke of this.strokes) this.redraw(stroke);
  }

  begin(style, pxPerMm, sample, visible) {
    this.current = visible ? { style, pxPerMm, points: [] } : null;
    if (this.current) {
      this.strokes.push(this.current);
      this.add([sample]);
    }
  }

  add(samples) {
    const stroke = this.current;
    if (!stroke) return;
    for (const s of samples) {
      const point = { px: s.px, py: s.py, pressure: s.pressure };
      this.segment(stroke, stroke.points[stroke.points.length - 1] || point, point);
      stroke.points.push(point);
    }
  }

  end() {
    this.current = null;
  }

  segment(stroke, from, to) {
    const { style, pxPerMm } = stroke;
    const pressure = (from.pressure + to.pressure) / 2;
    const scale = 1 - style.pressureShare + style.pressureShare * Math.min(1, pressure * 1.6);
    this.g.strokeStyle = style.color;
    this.g.lineWidth = Math.max(0.75, style.widthMm * pxPerMm * scale);
    this.g.beginPath();
    this.g.moveTo(from.px, from.py);
    this.g.lineTo(to.px, to.py);
    this.g.stroke();
  }

  redraw(stroke) {
    stroke.points.forEach((point, i) => this.segment(stroke, stroke.points[i - 1] || point, point));
  }

  clear() {
    this.strokes = [];
    this.current = null;
    this.g.clearRect(0, 0, this.canvas.width, this.canvas.height);
  }

  /** Canvas pixels that hold ink (alpha > 0): tests read it, hidden ink leaves it at 0. */
  inkedPixels() {
    const { width, height } = this.canvas;
    const data = this.g.getImageData(0, 0, width, height).data;
    let count = 0;
    for (let i = 3; i < data.length; i += 4) if (data[i] > 0) count += 1;
    return count;
  }
}
