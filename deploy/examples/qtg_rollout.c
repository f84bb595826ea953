/* Minimal C client of an exported QTG rollout model through onnxruntime's C API (spec/deploy.md §10).
 *
 * Build (onnxruntime's C package unpacked in $ORT, see deploy/README.md "Embedded use"):
 *   cc -O2 -Wall -Wextra qtg_rollout.c -I$ORT/include -L$ORT/lib -lonnxruntime -o qtg_rollout
 * Run:
 *   LD_LIBRARY_PATH=$ORT/lib ./qtg_rollout qtg_rollout.onnx [inputs.f32 [poses.f32]]
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
 * Without inputs.f32 every joint is at the identity rotation and the root at the origin. With it, the file holds
 * 2 * C * P little-endian float32 values: past then target, row-major. With poses.f32 the whole output (T * P
 * float32) is written there too.
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

int main(int argc, char** argv) {
  if (argc < 2 || argc > 4) {
    fprintf(stderr, "usage: %s qtg_rollout.onnx [inputs.f32 [poses.f32]]\n", argv[0]);
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
  char* model_json = NULL;
  check(ort->ModelMetadataLookupCustomMetadataMap(metadata, allocator, "model", &model_json));
  if (model_json != NULL) {
    printf("model: %s\n", model_json);
    check(ort->AllocatorFree(allocator, model_json));
  }
  char* join_json = NULL; /* absent: the network's frames as they are (join "none") */
  check(ort->ModelMetadataLookupCustomMetadataMap(metadata, allocator, "join", &join_json));
  if (join_json != NULL) {
    printf("join: %s\n", join_json);
    check(ort->AllocatorFree(allocator, join_json));
  } else {
    printf("join: none\n");
  }
  ort->ReleaseModelMetadata(metadata);

  /* sizes from the model's declared shapes: past/target (B, C, P), poses (B, T, P) */
  size_t n_inputs, n_outputs;
  check(ort->SessionGetInputCount(session, &n_inputs));
  check(ort->SessionGetOutputCount(session, &n_outputs));
  if (n_inputs != 2 || n_outputs != 1) fail("expected a rollout model: inputs past, target; output poses");
  int64_t past_dims[3], target_dims[3], out_dims[3];
  declared_shape(session, 1, 0, past_dims);
  declared_shape(session, 1, 1, target_dims);
  declared_shape(session, 0, 0, out_dims);
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
  if (rank != 3) fail("expected an output of rank 3");
  check(ort->GetDimensions(info, dims, 3));
  ort->ReleaseTensorTypeAndShapeInfo(info);
  if (dims[0] != 1 || dims[2] != P || dims[1] < 1) fail("unexpected output shape");
  float* poses;
  check(ort->GetTensorMutableData(output, (void**)&poses)); /* (1, T, P), valid until ReleaseValue */
  const int64_t T = dims[1];
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

  ort->ReleaseValue(output);
  ort->ReleaseValue(inputs[0]);
  ort->ReleaseValue(inputs[1]);
  ort->ReleaseMemoryInfo(memory);
  ort->ReleaseSession(session);
  ort->ReleaseSessionOptions(options);
  ort->ReleaseEnv(env);
  free(past);
  free(target);
  return 0;
}
