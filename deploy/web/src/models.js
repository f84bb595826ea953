// The served model folders (the server's manifest: each folder's files and every model's metadata, read by the
// server from the files' metadata_props) and onnxruntime-web sessions on its WebAssembly backend, one thread.
import * as ort from "/vendor/ort/ort.wasm.min.mjs";

ort.env.wasm.wasmPaths = "/vendor/ort/";
ort.env.wasm.numThreads = 1;
ort.env.wasm.proxy = false;

export async function fetchJson(url) {
  const r = await fetch(url, { cache: "no-store" });
  if (!r.ok) throw new Error(`${url}: HTTP ${r.status}`);
  return r.json();
}

export async function fetchBytes(url) {
  const r = await fetch(url, { cache: "no-store" });
  if (!r.ok) throw new Error(`${url}: HTTP ${r.status}`);
  return r.arrayBuffer();
}

const sessions = new Map();

export async function session(folder, file) {
  const key = `${folder.id}/${file}`;
  if (!sessions.has(key)) {
    if (!folder.files.includes(file)) throw new Error(`folder ${folder.label} has no ${file}`);
    const bytes = await fetchBytes(`/models/${folder.id}/${file}`);
    sessions.set(key, await ort.InferenceSession.create(new Uint8Array(bytes), { executionProviders: ["wasm"], graphOptimizationLevel: "all" }));
  }
  return sessions.get(key);
}

// The folder holds the model `name` with the files `needed`, or a one-line Error naming what it holds.
export function requireModel(folder, name, needed) {
  if (!folder) throw new Error(`no folder of ${name} models is served (python -m deploy web DIR: export one first)`);
  if (folder.model !== name) throw new Error(`folder ${folder.label} holds the models of ${folder.model}, not ${name}`);
  const missing = needed.filter((f) => !folder.files.includes(f));
  if (missing.length) throw new Error(`folder ${folder.label} has no ${missing.join(", ")}`);
}

export const tensor = (data, dims) => new ort.Tensor("float32", data instanceof Float32Array ? data : Float32Array.from(data), dims);

export { ort };
