/* Minimal C client of an exported QTG rollout model through onnxruntime's C API (spec/deploy.md §10).
 *
 * Build (onnxruntime's C package unpacked in $ORT, see deploy/README.md "Embedded use"):
 *   cc -O2 -Wall -Wextra qtg_rollout.c qtg_footlock.c -I$ORT/include -L$ORT/lib -lonnxruntime -lm -o qtg_rollout
 * Run:
 *   LD_LIBRARY_PATH=$ORT/lib ./qtg_rollout [--footlock] qtg_rollout.onnx [inputs.f32 [poses.f32]]
 *
 * Contract of the model (its "io" metadata): inputs "past" and "target", float32 (B, C, P) row-major (C = 2: the
 * two poses before and the two after the transition); output "poses" float32 (B, T, P). A pose is
 * [root translation (3) | J local joint quaternions (w, x, y, z)], P = 3 + 4 J (P = 91 for the 22-joint CMU
 * skeleton). Nothing is hard-coded here: C, P and T are read from the model's declared input and output shapes
 * (the batch axis is symbolic; this program runs B = 1). With in-graph normalisation (metadata "normalization":
 * {"in_graph": true}) poses are raw: root translation in centimetres, relative to the window's first pose (see
 * refimpl/protocols/transition.py).
 *
 * A model exported with the join option (`refimpl export --join inertialize`, metadata "join") has the joins
 * inertialised inside the graph (spec/qtg.md 7.4): nothing to do here, the poses it returns are already joined;
 * this program prints the metadata entry so that the user sees which variant runs.
 *
 * The portable target (`--target portable`, spec/deploy.md 13) has no rollout graph: give its qtg_init.onnx
 * (metadata model.role "init") and the program runs the host loop of its metadata over qtg_init.onnx,
 * qtg_step.onnx and, when present, qtg_join.onnx of the same folder (host_loop below).
 *
 * --footlock: after the rollout, pin the planted feet by two-bone IK (spec/qtg.md 7.5, qtg_footlock.c): with a
 * model exported with the join option this is `join="inertialize+footlock"`. It needs raw poses in centimetres
 * (metadata "normalization" with "in_graph": true) and the skeleton (metadata "skeleton": names, parents,
 * offsets) and frame rate ("frame_rate") the model was exported with; it works on p_-1, p_0 | poses | g1, g2.
 *
 * Without inputs.f32 every joint is at the identity rotation and the root at the origin. With it, the file holds
 * 2 * C * P little-endian float32 values: past then target, row-major. With poses.f32 the whole output (T * P
 * float32) is written there too.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <onnxruntime_c_api.h>

#include "qtg_footlock.h"

static const OrtApi* ort;

static void check(OrtStatus* status) {
  if (status != NULL) {
    fprintf(stderr, "onnxruntime: %s\n", ort->GetErrorMessage(status));
    ort->ReleaseStatus(status);
    exit(1);
  }
}

static void fail(const char* message) {
  fprintf(stderr, "qtg_rollout: %s\n", message);
  exit(1);
}

/* declared shape of input (is_input) or output `index`: rank 3 required; returns the dims */
static void declared_shape(OrtSession* session, int is_input, size_t index, int64_t dims[3]) {
  OrtTypeInfo* type_info;
  if (is_input)
    check(ort->SessionGetInputTypeInfo(session, index, &type_info));
  else
    check(ort->SessionGetOutputTypeInfo(session, index, &type_info));
  const OrtTensorTypeAndShapeInfo* tensor_info;
  check(ort->CastTypeInfoToTensorInfo(type_info, &tensor_info));
  if (tensor_info == NULL) fail("a model input or output is not a tensor");
  ONNXTensorElementDataType element;
  check(ort->GetTensorElementType(tensor_info, &element));
  if (element != ONNX_TENSOR_ELEMENT_DATA_TYPE_FLOAT) fail("expected float32 inputs and outputs");
  size_t rank;
  check(ort->GetDimensionsCount(tensor_info, &rank));
  if (rank != 3) fail("expected inputs and output of rank 3 (B, frames, P)");
  check(ort->GetDimensions(tensor_info, dims, 3)); /* -1 for a symbolic axis */
  ort->ReleaseTypeInfo(type_info);
}

/* the metadata entry `key` as a string to free() (NULL when absent) */
static char* metadata_entry(OrtModelMetadata* metadata, OrtAllocator* allocator, const char* key) {
  char* value = NULL;
  check(ort->ModelMetadataLookupCustomMetadataMap(metadata, allocator, key, &value));
  if (value == NULL) return NULL;
  const size_t n = strlen(value) + 1;
  char* copy = malloc(n);
  if (copy == NULL) fail("out of memory");
  memcpy(copy, value, n);
  check(ort->AllocatorFree(allocator, value));
  return copy;
}

/* --footlock: p_-1, p_0 | poses (T frames) | g1, g2 in double, foot locking, the T frames written back */
static void footlock(const char* skeleton_json, const char* rate_json, const char* norm_json, const float* past,
                     float* poses, const float* target, int64_t C, int64_t T, int64_t P) {
  if (norm_json == NULL || strstr(norm_json, "\"in_graph\": true") == NULL)
    fail("--footlock needs raw poses in centimetres: a model with metadata normalization.in_graph true");
  qtg_skeleton skeleton;
  if (qtg_skeleton_from_json(skeleton_json, &skeleton) != 0 || 3 + 4 * (int64_t)skeleton.joints != P)
    fail("--footlock needs the metadata entry skeleton (names, parents, offsets) of the pose's joints");
  const double rate = rate_json != NULL ? strtod(rate_json, NULL) : 30.0;
  const int64_t F = 2 * C + T;
  double* seq = malloc(sizeof *seq * (size_t)(F * P));
  if (seq == NULL) fail("out of memory");
  for (int64_t i = 0; i < C * P; ++i) seq[i] = past[i], seq[(C + T) * P + i] = target[i];
  for (int64_t i = 0; i < T * P; ++i) seq[C * P + i] = poses[i];
  const qtg_footlock_options options = qtg_footlock_defaults(rate);
  const int changed = qtg_footlock(&skeleton, &options, seq, (int)F, (int)C, (int)(C + T));
  if (changed < 0) fail(qtg_footlock_error(changed));
  for (int64_t i = 0; i < T * P; ++i) poses[i] = (float)seq[C * P + i];
  printf("footlock: %d of %lld frames changed (%d joints, %.6g fps)\n", changed, (long long)T, skeleton.joints,
         rate);
  free(seq);
  qtg_skeleton_free(&skeleton);
}

/* `name` in the folder of `path` (malloc'd) */
static char* sibling(const char* path, const char* name) {
  const char* slash = strrchr(path, '/');
  const size_t dir = slash == NULL ? 0 : (size_t)(slash - path + 1);
  char* out = malloc(dir + strlen(name) + 1);
  if (out == NULL) fail("out of memory");
  memcpy(out, path, dir);
  strcpy(out + dir, name);
  return out;
}

/* The host loop of the portable graphs (their metadata "target": "host_loop"; spec/deploy.md 13): `init` on
 * past/target, T calls of qtg_step.onnx carrying pose, latent_prev and hidden (target_latent fixed; the outputs
 * of one Run are the inputs of the next), then qtg_join.onnx when the folder has one. Returns T * P floats. */
static float* host_loop(OrtEnv* env, OrtSessionOptions* options, const char* init_path, OrtSession* init,
                        OrtValue* const inputs[2], OrtMemoryInfo* memory, int64_t T, int64_t P) {
  char* step_path = sibling(init_path, "qtg_step.onnx");
  char* join_path = sibling(init_path, "qtg_join.onnx");
  OrtSession *step, *join = NULL;
  check(ort->CreateSession(env, step_path, options, &step));
  FILE* probe = fopen(join_path, "rb");
  if (probe != NULL) {
    fclose(probe);
    check(ort->CreateSession(env, join_path, options, &join));
  }
  const char* context_names[2] = {"past", "target"};
  const char* state_names[4] = {"pose", "latent_prev", "hidden", "target_latent"};
  const char* step_names[3] = {"pose_next", "latent_prev_next", "hidden_next"};
  OrtValue* state[4] = {NULL, NULL, NULL, NULL};
  check(ort->Run(init, NULL, context_names, (const OrtValue* const*)inputs, 2, state_names, 4, state));
  float* poses = malloc(sizeof *poses * (size_t)(T * P));
  if (poses == NULL) fail("out of memory");
  for (int64_t t = 0; t < T; ++t) {
    OrtValue* next[3] = {NULL, NULL, NULL};
    check(ort->Run(step, NULL, state_names, (const OrtValue* const*)state, 4, step_names, 3, next));
    float* pose;
    check(ort->GetTensorMutableData(next[0], (void**)&pose)); /* (1, P) */
    memcpy(poses + t * P, pose, sizeof *poses * (size_t)P);
    for (int i = 0; i < 3; ++i) ort->ReleaseValue(state[i]), state[i] = next[i];
  }
  for (int i = 0; i < 4; ++i) ort->ReleaseValue(state[i]);
  if (join != NULL) { /* the join option as its own graph: past, poses (1, T, P), target -> poses_joined */
    const int64_t shape[3] = {1, T, P};
    OrtValue* join_inputs[3] = {inputs[0], NULL, inputs[1]};
    check(ort->CreateTensorWithDataAsOrtValue(memory, poses, sizeof *poses * (size_t)(T * P), shape, 3,
                                              ONNX_TENSOR_ELEMENT_DATA_TYPE_FLOAT, &join_inputs[1]));
    const char* join_names[3] = {"past", "poses", "target"};
    const char* joined_name[1] = {"poses_joined"};
    OrtValue* joined = NULL;
    check(ort->Run(join, NULL, join_names, (const OrtValue* const*)join_inputs, 3, joined_name, 1, &joined));
    float* values;
    check(ort->GetTensorMutableData(joined, (void**)&values));
    memcpy(poses, values, sizeof *poses * (size_t)(T * P));
    ort->ReleaseValue(joined);
    ort->ReleaseValue(join_inputs[1]);
    ort->ReleaseSession(join);
    printf("host loop: init, %lld steps, qtg_join.onnx\n", (long long)T);
  } else {
    printf("host loop: init, %lld steps\n", (long long)T);
  }
  ort->ReleaseSession(step);
  free(step_path), free(join_path);
  return poses;
}

int main(int argc, char** argv) {
  const char* program = argv[0];
  const int lock = argc >= 2 && strcmp(argv[1], "--footlock") == 0; /* then argv[1] is the model */
  if (lock) --argc, ++argv;
  if (argc < 2 || argc > 4) {
    fprintf(stderr, "usage: %s [--footlock] qtg_rollout.onnx|qtg_init.onnx [inputs.f32 [poses.f32]]\n", program);
    return 2;
  }
  ort = OrtGetApiBase()->GetApi(ORT_API_VERSION);
  if (ort == NULL) {
    /* the header's ORT_API_VERSION is newer than the shared library: use headers of the library's version */
    fprintf(stderr, "qtg_rollout: onnxruntime %s does not provide C API version %d\n",
            OrtGetApiBase()->GetVersionString(), ORT_API_VERSION);
    return 1;
  }

  /* session: one intra-op thread, sequential, no spinning threads (spec/deploy.md §7) */
  OrtEnv* env;
  check(ort->CreateEnv(ORT_LOGGING_LEVEL_WARNING, "qtg", &env));
  OrtSessionOptions* options;
  check(ort->CreateSessionOptions(&options));
  check(ort->SetIntraOpNumThreads(options, 1));
  check(ort->SetInterOpNumThreads(options, 1));
  check(ort->SetSessionExecutionMode(options, ORT_SEQUENTIAL));
  check(ort->SetSessionGraphOptimizationLevel(options, ORT_ENABLE_ALL));
  check(ort->AddSessionConfigEntry(options, "session.intra_op.allow_spinning", "0"));
  OrtSession* session;
  check(ort->CreateSession(env, argv[1], options, &session)); /* wchar_t* path on Windows */

  /* metadata values are JSON strings: parse them with any JSON reader */
  OrtAllocator* allocator;
  check(ort->GetAllocatorWithDefaultOptions(&allocator));
  OrtModelMetadata* metadata;
  check(ort->SessionGetModelMetadata(session, &metadata));
  char* model_json = metadata_entry(metadata, allocator, "model");
  if (model_json != NULL) printf("model: %s\n", model_json);
  /* role "init" (the portable target: no rollout graph): the host loop over qtg_init/step(/join).onnx */
  const int host = model_json != NULL && strstr(model_json, "\"role\": \"init\"") != NULL;
  char* join_json = NULL; /* absent: the network's frames as they are (join "none") */
  check(ort->ModelMetadataLookupCustomMetadataMap(metadata, allocator, "join", &join_json));
  if (join_json != NULL) {
    printf("join: %s\n", join_json);
    check(ort->AllocatorFree(allocator, join_json));
  } else {
    printf("join: none\n");
  }
  char* skeleton_json = lock ? metadata_entry(metadata, allocator, "skeleton") : NULL;
  char* rate_json = lock ? metadata_entry(metadata, allocator, "frame_rate") : NULL;
  char* norm_json = lock ? metadata_entry(metadata, allocator, "normalization") : NULL;
  ort->ReleaseModelMetadata(metadata);

  /* sizes from the model's declared shapes: past/target (B, C, P), poses (B, T, P) */
  size_t n_inputs, n_outputs;
  check(ort->SessionGetInputCount(session, &n_inputs));
  check(ort->SessionGetOutputCount(session, &n_outputs));
  if (n_inputs != 2 || n_outputs != (host ? 4 : 1))
    fail("expected a rollout model (inputs past, target; output poses) or an init model (4 outputs)");
  int64_t past_dims[3], target_dims[3], out_dims[3] = {1, -1, -1};
  declared_shape(session, 1, 0, past_dims);
  declared_shape(session, 1, 1, target_dims);
  if (host) { /* T from the metadata's model.config.transition_length */
    const char* t = strstr(model_json, "\"transition_length\": ");
    out_dims[1] = t != NULL ? strtoll(t + strlen("\"transition_length\": "), NULL, 10) : -1;
    out_dims[2] = past_dims[2];
    if (out_dims[1] < 1) fail("the init model's metadata has no model.config.transition_length");
  } else {
    declared_shape(session, 0, 0, out_dims);
  }
  const int64_t C = past_dims[1], P = past_dims[2];
  if (C < 1 || P < 3 || target_dims[1] != C || target_dims[2] != P || (out_dims[2] != P && out_dims[2] != -1))
    fail("inconsistent or symbolic context/pose sizes in the model's inputs");
  printf("sizes: context C = %lld, pose P = %lld, T = %lld (declared; -1 = symbolic)\n", (long long)C,
         (long long)P, (long long)out_dims[1]);

  /* inputs: batch 1 */
  const size_t count = (size_t)(C * P);
  float* past = calloc(count, sizeof *past);
  float* target = calloc(count, sizeof *target);
  if (past == NULL || target == NULL) fail("out of memory");
  if (argc >= 3) {
    FILE* f = fopen(argv[2], "rb");
    if (f == NULL) fail("cannot open the inputs file");
    if (fread(past, sizeof *past, count, f) != count || fread(target, sizeof *target, count, f) != count)
      fail("the inputs file must hold 2 * C * P float32 values (past, then target)");
    fclose(f);
  } else { /* every joint at the identity rotation (w = 1), the root at the origin */
    for (int64_t k = 0; k < C; ++k)
      for (int64_t i = 3; i + 3 < P; i += 4) past[k * P + i] = target[k * P + i] = 1.0f;
  }
  const int64_t shape[3] = {1, C, P};
  OrtMemoryInfo* memory;
  check(ort->CreateCpuMemoryInfo(OrtArenaAllocator, OrtMemTypeDefault, &memory));
  OrtValue* inputs[2] = {NULL, NULL};
  check(ort->CreateTensorWithDataAsOrtValue(memory, past, count * sizeof *past, shape, 3,
                                            ONNX_TENSOR_ELEMENT_DATA_TYPE_FLOAT, &inputs[0]));
  check(ort->CreateTensorWithDataAsOrtValue(memory, target, count * sizeof *target, shape, 3,
                                            ONNX_TENSOR_ELEMENT_DATA_TYPE_FLOAT, &inputs[1]));

  /* one call generates the whole transition (or the host loop of the portable graphs) */
  const char* input_names[2] = {"past", "target"};
  const char* output_names[1] = {"poses"};
  OrtValue* output = NULL;
  int64_t dims[3] = {1, out_dims[1], P};
  size_t rank = 3;
  float* poses;
  if (host) {
    poses = host_loop(env, options, argv[1], session, inputs, memory, dims[1], P);
  } else {
    check(ort->Run(session, NULL, input_names, (const OrtValue* const*)inputs, 2, output_names, 1, &output));
    OrtTensorTypeAndShapeInfo* info;
    check(ort->GetTensorTypeAndShape(output, &info));
    check(ort->GetDimensionsCount(info, &rank));
    if (rank != 3) fail("expected an output of rank 3");
    check(ort->GetDimensions(info, dims, 3));
    ort->ReleaseTensorTypeAndShapeInfo(info);
    if (dims[0] != 1 || dims[2] != P || dims[1] < 1) fail("unexpected output shape");
    check(ort->GetTensorMutableData(output, (void**)&poses)); /* (1, T, P), valid until ReleaseValue */
  }
  const int64_t T = dims[1];
  if (lock) footlock(skeleton_json, rate_json, norm_json, past, poses, target, C, T, P);
  printf("poses: rank %zu, shape (%lld, %lld, %lld)\n", rank, (long long)dims[0], (long long)T, (long long)dims[2]);
  const int64_t shown[2] = {0, T - 1}; /* first and last frame (once when T = 1) */
  for (int k = 0; k < (T > 1 ? 2 : 1); ++k) {
    const float* p = poses + shown[k] * P;
    printf("frame %lld: root %.6f %.6f %.6f", (long long)(shown[k] + 1), p[0], p[1], p[2]);
    if (P >= 7) printf(", first joint q %.6f %.6f %.6f %.6f", p[3], p[4], p[5], p[6]);
    printf("\n");
  }
  if (argc >= 4) {
    FILE* f = fopen(argv[3], "wb");
    if (f == NULL || fwrite(poses, sizeof *poses, (size_t)(T * P), f) != (size_t)(T * P) || fclose(f) != 0)
      fail("cannot write the poses file");
  }

  if (host)
    free(poses);
  else
    ort->ReleaseValue(output);
  ort->ReleaseValue(inputs[0]);
  ort->ReleaseValue(inputs[1]);
  ort->ReleaseMemoryInfo(memory);
  ort->ReleaseSession(session);
  ort->ReleaseSessionOptions(options);
  ort->ReleaseEnv(env);
  free(past);
  free(target);
  free(skeleton_json), free(rate_json), free(norm_json), free(model_json);
  return 0;
}
