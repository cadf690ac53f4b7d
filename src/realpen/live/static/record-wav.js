// @ts-check
// A take's microphone samples as a 16-bit PCM WAV, and its upload to the server in chunks
// that each fit the server's request-body limit (64 KiB).

/** Bytes per upload request: under the server's 64 KiB body limit. */
export const CHUNK_BYTES = 60 * 1024;

/**
 * Float samples (full scale ±1) as a mono 16-bit PCM WAV. 16-bit keeps 96 dB of a microphone's
 * range at half the bytes of float; samples beyond full scale are clamped (and counted).
 * @param {Float32Array[]} blocks the samples, in order
 * @param {number} rate the sampling rate, Hz
 * @returns {{ wav: Uint8Array, frames: number, clipped: number, peak: number }}
 */
export function wav16(blocks, rate) {
  const frames = blocks.reduce((n, block) => n + block.length, 0);
  const bytes = new Uint8Array(44 + frames * 2);
  const view = new DataView(bytes.buffer);
  const text = (/** @type {number} */ at, /** @type {string} */ s) => {
    for (let i = 0; i < s.length; i += 1) view.setUint8(at + i, s.charCodeAt(i));
  };
  text(0, 'RIFF');
  view.setUint32(4, 36 + frames * 2, true);
  text(8, 'WAVE');
  text(12, 'fmt ');
  view.setUint32(16, 16, true);
  view.setUint16(20, 1, true); // PCM
  view.setUint16(22, 1, true); // mono
  view.setUint32(24, rate, true);
  view.setUint32(28, rate * 2, true);
  view.setUint16(32, 2, true);
  view.setUint16(34, 16, true);
  text(36, 'data');
  view.setUint32(40, frames * 2, true);
  let at = 44;
  let clipped = 0;
  let peak = 0;
  for (const block of blocks) {
    for (let i = 0; i < block.length; i += 1) {
      const x = block[i];
      const magnitude = Math.abs(x);
      if (magnitude > peak) peak = magnitude;
      if (magnitude >= 0.999) clipped += 1;
      const clamped = Math.max(-1, Math.min(1, x));
      view.setInt16(at, Math.round(clamped < 0 ? clamped * 32768 : clamped * 32767), true);
      at += 2;
    }
  }
  return { wav: bytes, frames, clipped, peak };
}

/**
 * Upload a WAV to a take in chunks, then say it is complete; the server checks and measures it.
 * @param {(url: string) => string} withToken adds the LAN token to a URL
 * @param {number} takeId the take
 * @param {Uint8Array} wav the file's bytes
 * @param {(done: number, total: number) => void} [progress] bytes sent so far
 * @returns {Promise<object>} the take as the server lists it
 */
export async function uploadWav(withToken, takeId, wav, progress) {
  for (let offset = 0; offset < wav.length; offset += CHUNK_BYTES) {
    const chunk = wav.slice(offset, Math.min(offset + CHUNK_BYTES, wav.length)); // its own buffer
    const response = await fetch(withToken(`api/record/takes/${takeId}/sound?offset=${offset}`), {
      method: 'PUT', headers: { 'Content-Type': 'application/octet-stream' }, body: chunk,
    });
    if (!response.ok) throw new Error(await problem(response));
    if (progress) progress(offset + chunk.length, wav.length);
  }
  const response = await fetch(withToken(`api/record/takes/${takeId}/sound`), { method: 'POST' });
  if (!response.ok) throw new Error(await problem(response));
  return response.json();
}

/**
 * The server's one-line reason for a refusal (its `detail`), else the status.
 * @param {Response} response
 * @returns {Promise<string>}
 */
export async function problem(response) {
  try {
    const { detail } = await response.json();
    if (typeof detail === 'string' && detail) return detail;
  } catch { /* not JSON */ }
  return `HTTP ${response.status}`;
}
