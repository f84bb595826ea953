// QuaterNet short-term in the page: an exp-map clip at the model's rate (refimpl.tasks.prediction.load_clip:
// the CMU reference row dropped, every stride-th frame, quat_fix) and the k frames the predict graph continues
// from the prefix ending at a chosen frame (the graph applies the sign rule itself: input_transform.in_graph).
// Shapes: a clip F x J x 4; prefix P frames; k predicted frames.
import { parseExpmap } from "./formats.js";
import { quatFix } from "./math.js";

const FILE_RATE = { cmu: 120, h36m: 50 };

export function clipForPredictor(text, meta, where) {
  const J = meta.skeleton.names.length;
  const dataset = meta.dataset;
  if (!(dataset in FILE_RATE)) throw new Error(`the model names no prediction dataset (cmu or h36m)`);
  let { rot } = parseExpmap(text, J, where);
  if (dataset === "cmu") rot = rot.slice(1);
  const stride = Math.max(1, Math.round(FILE_RATE[dataset] / meta.frame_rate));
  const out = [];
  for (let f = 0; f < rot.length; f += stride) out.push(rot[f]);
  return quatFix(out);
}

// `predict(prefix Float32Array, P) -> k x 4J numbers`; returns {prefix: P x J x 4, pred: k x J x 4 (unit), truth}.
export async function continueClip(predict, rot, frame, P) {
  if (!(Number.isInteger(frame) && frame >= P - 1 && frame <= rot.length - 1)) throw new Error(`frame: expected ${P - 1} ... ${rot.length - 1} (a ${P}-frame prefix ending there), got ${frame}`);
  const prefix = rot.slice(frame - P + 1, frame + 1);
  const J = prefix[0].length;
  const out = await predict(Float32Array.from(prefix.flat(2)), P);
  const pred = out.map((row) => {
    const f = [];
    for (let j = 0; j < J; j++) {
      const q = row.slice(4 * j, 4 * j + 4), n = Math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
      f.push(q.map((v) => v / n));
    }
    return f;
  });
  return { prefix, pred, truth: rot.slice(frame + 1, frame + 1 + pred.length) };
}
