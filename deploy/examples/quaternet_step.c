/* QuaterNet's online loop in C through onnxruntime's C API: one step per frame with a carried GRU state
 * (spec/deploy.md §10, deploy/README.md "Embedded use").
 *
 * Build (onnxruntime's C package unpacked in $ORT, see deploy/README.md):
 *   cc -O2 -Wall -Wextra quaternet_step.c -I$ORT/include -L$ORT/lib -lonnxruntime -lm -o quaternet_step
 * Run:
 *   LD_LIBRARY_PATH=$ORT/lib ./quaternet_step MODEL_DIR prefix.f32 P k [frames.f32]
 *
 * MODEL_DIR holds quaternet_init.onnx and quaternet_step.onnx (python -m deploy export / refimpl export).
 * prefix.f32 holds P frames of F little-endian float32 (frame t = J joint quaternions (w, x, y, z), joint-major,
 * then any further values of the frame). The program prints the k predicted frames' first values and writes all
 * k * F values to frames.f32.
 *
 * Everything comes from the models: F, L, H from the declared shapes of step's inputs x (B, F) and hidden
 * (L, B, H); J and the frame kind from the metadata entry "representation" (JSON; read with two strstr calls:
 * the exporter writes JSON with sorted keys and ", " / ": " separators), and whether the sign rule must be applied
 * here from "input_transform" ("in_graph": false for the step model). The sign rule (metadata input_transform,
 * deploy/README.md "QuaterNet"): unit length; frame 0 per joint s0 = (-1)^(n(alpha) + n(gamma)) from
 * sigma = atan2(z + x, w - y), delta = atan2(z - x, w + y); frame t: s0 (-1)^c_t with c_t the number of negative
 * consecutive dot products up to t.
 *
 * Loop: hidden = init(x_0); for t < P: (y, hidden) = step(x_t, hidden); then k - 1 times (y, hidden) = step(y,
 * hidden). The outputs of one call are the inputs of the next (no copies).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <onnxruntime_c_api.h>

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

static const OrtApi* ort;

static void check(OrtStatus* status) {
  if (status != NULL) {
    fprintf(stderr, "onnxruntime: %s\n", ort->GetErrorMessage(status));
    ort->ReleaseStatus(status);
    exit(1);
  }
}

static void fail(const char* message) {
  fprintf(stderr, "quaternet_step: %s\n", message);
  exit(1);
}

static OrtSession* open_session(OrtEnv* env, OrtSessionOptions* options, const char* dir, const char* file) {
  char path[4096];
  if (snprintf(path, sizeof path, "%s/%s", dir, file) >= (int)sizeof path) fail("model path too long");
  OrtSession* session;
  check(ort->CreateSession(env, path, options, &session));
  return session;
}

/* declared dims of input `index` of `session` (rank `rank`; -1 for a symbolic axis) */
static void input_dims(OrtSession* session, size_t index, size_t rank, int64_t* dims) {
  OrtTypeInfo* type_info;
  check(ort->SessionGetInputTypeInfo(session, index, &type_info));
  const OrtTensorTypeAndShapeInfo* tensor_info;
  check(ort->CastTypeInfoToTensorInfo(type_info, &tensor_info));
  if (tensor_info == NULL) fail("a model input is not a tensor");
  size_t got;
  check(ort->GetDimensionsCount(tensor_info, &got));
  if (got != rank) fail("unexpected rank of a model input");
  check(ort->GetDimensions(tensor_info, dims, rank));
  ort->ReleaseTypeInfo(type_info);
}

/* the JSON text of metadata entry `key` (caller frees with free) or NULL */
static char* metadata_json(OrtSession* session, const char* key) {
  OrtAllocator* allocator;
  check(ort->GetAllocatorWithDefaultOptions(&allocator));
  OrtModelMetadata* metadata;
  check(ort->SessionGetModelMetadata(session, &metadata));
  char* value = NULL;
  check(ort->ModelMetadataLookupCustomMetadataMap(metadata, allocator, key, &value));
  char* copy = NULL;
  if (value != NULL) {
    copy = malloc(strlen(value) + 1);
    if (copy == NULL) fail("out of memory");
    strcpy(copy, value);
    check(ort->AllocatorFree(allocator, value));
  }
  ort->ReleaseModelMetadata(metadata);
  return copy;
}

static int wraps(double v) { return v >= M_PI || v < -M_PI; }

/* the metadata's sign rule on P frames of F values whose first 4 J are joint quaternions (in place) */
static void canonical_signs(float* frames, long P, long F, long J) {
  for (long j = 0; j < J; ++j) {
    double sign = 1.0, prev[4] = {0, 0, 0, 0};
    for (long t = 0; t < P; ++t) {
      float* q = frames + t * F + 4 * j;
      double n = sqrt((double)q[0] * q[0] + (double)q[1] * q[1] + (double)q[2] * q[2] + (double)q[3] * q[3]);
      double u[4] = {q[0] / n, q[1] / n, q[2] / n, q[3] / n};
      if (t == 0) {
        double w = u[0], x = u[1], y = u[2], z = u[3];
        double sigma = atan2(z + x, w - y), delta = atan2(z - x, w + y), alpha, gamma;
        if (hypot(z - x, w + y) <= 1.49e-8) {
          alpha = 2 * sigma, gamma = 0;
        } else if (hypot(z + x, w - y) <= 1.49e-8) {
          alpha = 2 * delta, gamma = 0;
        } else {
          alpha = sigma + delta, gamma = sigma - delta;
        }
        sign = ((wraps(alpha) + wraps(gamma)) % 2) ? -1.0 : 1.0;
      } else if (u[0] * prev[0] + u[1] * prev[1] + u[2] * prev[2] + u[3] * prev[3] < 0) {
        sign = -sign;
      }
      for (int i = 0; i < 4; ++i) {
        prev[i] = u[i];
        q[i] = (float)(sign * u[i]);
      }
    }
  }
}

/* one Run of the step model: inputs x, hidden; outputs y, hidden_next (new values the caller releases) */
static void step(OrtSession* session, OrtValue* x, OrtValue* hidden, OrtValue** y, OrtValue** hidden_next) {
  const char* in_names[2] = {"x", "hidden"};
  const char* out_names[2] = {"y", "hidden_next"};
  const OrtValue* inputs[2] = {x, hidden};
  OrtValue* outputs[2] = {NULL, NULL};
  check(ort->Run(session, NULL, in_names, inputs, 2, out_names, 2, outputs));
  *y = outputs[0];
  *hidden_next = outputs[1];
}

int main(int argc, char** argv) {
  if (argc < 5 || argc > 6) {
    fprintf(stderr, "usage: %s MODEL_DIR prefix.f32 P k [frames.f32]\n", argv[0]);
    return 2;
  }
  const long P = strtol(argv[3], NULL, 10), K = strtol(argv[4], NULL, 10);
  if (P < 1 || K < 1) {
    fprintf(stderr, "quaternet_step: P and k must be positive integers\n");
    return 2;
  }
  ort = OrtGetApiBase()->GetApi(ORT_API_VERSION);
  if (ort == NULL) {
    fprintf(stderr, "quaternet_step: onnxruntime %s does not provide C API version %d\n",
            OrtGetApiBase()->GetVersionString(), ORT_API_VERSION);
    return 1;
  }
  OrtEnv* env;
  check(ort->CreateEnv(ORT_LOGGING_LEVEL_WARNING, "quaternet", &env));
  OrtSessionOptions* options;
  check(ort->CreateSessionOptions(&options));
  check(ort->SetIntraOpNumThreads(options, 1));
  check(ort->SetInterOpNumThreads(options, 1));
  check(ort->SetSessionExecutionMode(options, ORT_SEQUENTIAL));
  check(ort->AddSessionConfigEntry(options, "session.intra_op.allow_spinning", "0")); /* two sessions */
  OrtSession* init = open_session(env, options, argv[1], "quaternet_init.onnx");
  OrtSession* stepper = open_session(env, options, argv[1], "quaternet_step.onnx");

  /* sizes from the declared shapes, frame kind and J from the metadata */
  int64_t xd[2], hd[3];
  input_dims(stepper, 0, 2, xd);
  input_dims(stepper, 1, 3, hd);
  const long F = (long)xd[1], L = (long)hd[0], H = (long)hd[2];
  if (F < 4 || L < 1 || H < 1) fail("unexpected declared sizes of x (B, F) / hidden (L, B, H)");
  char* rep = metadata_json(stepper, "representation");
  char* transform = metadata_json(stepper, "input_transform");
  if (rep == NULL || strstr(rep, "\"name\": \"quaternet_frame\"") == NULL)
    fail("expected quaternion frames (metadata representation.name quaternet_frame); a dual-quaternion model "
         "needs the conversion of deploy/README.md first");
  const char* joints = strstr(rep, "\"joints\": ");
  const long J = joints ? strtol(joints + strlen("\"joints\": "), NULL, 10) : 0;
  if (J < 1 || 4 * J > F) fail("metadata representation: no usable joint count");
  const int apply_rule = transform != NULL && strstr(transform, "\"in_graph\": false") != NULL;
  printf("sizes: F = %ld, J = %ld, L = %ld, H = %ld; sign rule applied here: %s\n", F, J, L, H,
         apply_rule ? "yes" : "no (in the graph)");
  free(rep);
  free(transform);

  /* the prefix, canonicalised */
  float* prefix = malloc((size_t)(P * F) * sizeof *prefix);
  if (prefix == NULL) fail("out of memory");
  FILE* f = fopen(argv[2], "rb");
  if (f == NULL) fail("cannot open the prefix file");
  if (fread(prefix, sizeof *prefix, (size_t)(P * F), f) != (size_t)(P * F)) fail("the prefix file must hold P * F float32");
  fclose(f);
  if (apply_rule) canonical_signs(prefix, P, F, J);

  OrtMemoryInfo* memory;
  check(ort->CreateCpuMemoryInfo(OrtArenaAllocator, OrtMemTypeDefault, &memory));
  const int64_t frame_shape[2] = {1, F};
  OrtValue* x;
  check(ort->CreateTensorWithDataAsOrtValue(memory, prefix, (size_t)F * sizeof *prefix, frame_shape, 2,
                                            ONNX_TENSOR_ELEMENT_DATA_TYPE_FLOAT, &x));
  /* init: the learned initial state for a batch of 1 */
  const char* init_in[1] = {"x"};
  const char* init_out[1] = {"hidden"};
  OrtValue* hidden = NULL;
  check(ort->Run(init, NULL, init_in, (const OrtValue* const*)&x, 1, init_out, 1, &hidden));
  ort->ReleaseValue(x);

  OrtValue* y = NULL;
  for (long t = 0; t < P; ++t) { /* the prefix, frame by frame, the state carried */
    OrtValue *frame, *y_new, *h_new;
    check(ort->CreateTensorWithDataAsOrtValue(memory, prefix + t * F, (size_t)F * sizeof *prefix, frame_shape, 2,
                                              ONNX_TENSOR_ELEMENT_DATA_TYPE_FLOAT, &frame));
    step(stepper, frame, hidden, &y_new, &h_new);
    ort->ReleaseValue(frame);
    ort->ReleaseValue(hidden);
    if (y != NULL) ort->ReleaseValue(y);
    y = y_new;
    hidden = h_new;
  }
  float* out = malloc((size_t)(K * F) * sizeof *out);
  if (out == NULL) fail("out of memory");
  for (long k = 0; k < K; ++k) { /* y is the prediction of the next frame; feed it back */
    float* data;
    check(ort->GetTensorMutableData(y, (void**)&data));
    memcpy(out + k * F, data, (size_t)F * sizeof *out);
    if (k == 0 || k == K - 1)
      printf("frame %ld: joint 0 q %.6f %.6f %.6f %.6f\n", k + 1, data[0], data[1], data[2], data[3]);
    if (k + 1 < K) {
      OrtValue *y_new, *h_new;
      step(stepper, y, hidden, &y_new, &h_new);
      ort->ReleaseValue(y);
      ort->ReleaseValue(hidden);
      y = y_new;
      hidden = h_new;
    }
  }
  if (argc == 6) {
    FILE* o = fopen(argv[5], "wb");
    if (o == NULL || fwrite(out, sizeof *out, (size_t)(K * F), o) != (size_t)(K * F) || fclose(o) != 0)
      fail("cannot write the frames file");
  }
  ort->ReleaseValue(y);
  ort->ReleaseValue(hidden);
  ort->ReleaseMemoryInfo(memory);
  ort->ReleaseSession(stepper);
  ort->ReleaseSession(init);
  ort->ReleaseSessionOptions(options);
  ort->ReleaseEnv(env);
  free(prefix);
  free(out);
  return 0;
}
