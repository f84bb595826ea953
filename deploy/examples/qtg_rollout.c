/* Minimal C client of an exported QTG rollout model through onnxruntime's C API (spec/deploy.md §10).
 *
 * Build (onnxruntime release package unpacked in $ORT):
 *   cc -O2 qtg_rollout.c -I$ORT/include -L$ORT/lib -lonnxruntime -o qtg_rollout
 * Run:
 *   LD_LIBRARY_PATH=$ORT/lib ./qtg_rollout qtg_rollout.onnx
 *
 * Contract of the model (its "io" metadata): inputs "past" and "target", float32 (B, 2, P) row-major, the two
 * poses before and the two after the transition; output "poses" float32 (B, T, P). A pose is
 * [root translation (3) | 22 local joint quaternions (w, x, y, z)], P = 91. With in-graph normalisation (metadata
 * "normalization": {"in_graph": true}) poses are raw: root translation in centimetres, relative to the window's
 * first pose (see refimpl/transitions.py).
 */
#include <stdio.h>
#include <stdlib.h>

#include <onnxruntime_c_api.h>

static const OrtApi* ort;

static void check(OrtStatus* status) {
  if (status != NULL) {
    fprintf(stderr, "onnxruntime: %s\n", ort->GetErrorMessage(status));
    ort->ReleaseStatus(status);
    exit(1);
  }
}

int main(int argc, char** argv) {
  if (argc < 2) {
    fprintf(stderr, "usage: %s qtg_rollout.onnx\n", argv[0]);
    return 2;
  }
  ort = OrtGetApiBase()->GetApi(ORT_API_VERSION);

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
  char* model_json = NULL;
  check(ort->ModelMetadataLookupCustomMetadataMap(metadata, allocator, "model", &model_json));
  if (model_json != NULL) {
    printf("model: %s\n", model_json);
    check(ort->AllocatorFree(allocator, model_json));
  }
  ort->ReleaseModelMetadata(metadata);

  /* inputs: batch 1; here every joint at the identity rotation (w = 1) and the root at the origin */
  enum { P = 91 };
  float past[2 * P] = {0}, target[2 * P] = {0};
  for (int k = 0; k < 2; ++k)
    for (int j = 0; j < (P - 3) / 4; ++j) past[k * P + 3 + 4 * j] = target[k * P + 3 + 4 * j] = 1.0f;
  const int64_t shape[3] = {1, 2, P};
  OrtMemoryInfo* memory;
  check(ort->CreateCpuMemoryInfo(OrtArenaAllocator, OrtMemTypeDefault, &memory));
  OrtValue* inputs[2] = {NULL, NULL};
  check(ort->CreateTensorWithDataAsOrtValue(memory, past, sizeof past, shape, 3,
                                            ONNX_TENSOR_ELEMENT_DATA_TYPE_FLOAT, &inputs[0]));
  check(ort->CreateTensorWithDataAsOrtValue(memory, target, sizeof target, shape, 3,
                                            ONNX_TENSOR_ELEMENT_DATA_TYPE_FLOAT, &inputs[1]));

  /* one call generates the whole transition */
  const char* input_names[2] = {"past", "target"};
  const char* output_names[1] = {"poses"};
  OrtValue* output = NULL;
  check(ort->Run(session, NULL, input_names, (const OrtValue* const*)inputs, 2, output_names, 1, &output));

  OrtTensorTypeAndShapeInfo* info;
  check(ort->GetTensorTypeAndShape(output, &info));
  int64_t dims[3];
  size_t rank;
  check(ort->GetDimensionsCount(info, &rank));
  check(ort->GetDimensions(info, dims, 3));
  ort->ReleaseTensorTypeAndShapeInfo(info);
  float* poses;
  check(ort->GetTensorMutableData(output, (void**)&poses)); /* (1, T, P), valid until ReleaseValue */
  const int64_t T = dims[1];
  printf("poses: rank %zu, shape (%lld, %lld, %lld)\n", rank, (long long)dims[0], (long long)T, (long long)dims[2]);
  for (int64_t t = 0; t < T; t += T - 1)
    printf("frame %lld: root %.6f %.6f %.6f, hips q %.6f %.6f %.6f %.6f\n", (long long)(t + 1),
           poses[t * P + 0], poses[t * P + 1], poses[t * P + 2],
           poses[t * P + 3], poses[t * P + 4], poses[t * P + 5], poses[t * P + 6]);

  ort->ReleaseValue(output);
  ort->ReleaseValue(inputs[0]);
  ort->ReleaseValue(inputs[1]);
  ort->ReleaseMemoryInfo(memory);
  ort->ReleaseSession(session);
  ort->ReleaseSessionOptions(options);
  ort->ReleaseEnv(env);
  return 0;
}
