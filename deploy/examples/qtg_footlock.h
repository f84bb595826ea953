/* Foot locking of a generated QTG transition in C: spec/qtg.md 7.5 (`join="inertialize+footlock"`), the same
 * steps as refimpl/protocols/transition_footlock.py (lock_feet), in double precision.
 *
 * A planted foot of the generated frames is pinned where it landed (or where the context holds it) and the leg is
 * bent by analytic two-bone IK to reach the pin. It runs AFTER the exported graph (the rollout with the join
 * option, or init + T steps followed by the join), on the whole sequence p_-1, p_0 | G_1 ... G_T | g1, g2 in the
 * window frame, centimetres, y up (raw poses: in-graph normalisation or none). Plain C99, no allocation by the
 * caller beyond the sequence, no dependency but <math.h>.
 *
 * Pose layout (the models' "io" metadata): [root translation (3) | J local joint quaternions (w, x, y, z)],
 * P = 3 + 4 J, row-major frames.
 */
#ifndef QTG_FOOTLOCK_H
#define QTG_FOOTLOCK_H

#ifdef __cplusplus
extern "C" {
#endif

/* spec/qtg.md 7.5: FOOTLOCK_HEIGHT_CM, FOOTLOCK_SPEED_CM_S, FOOTLOCK_BLEND_FRAMES */
#define QTG_FOOTLOCK_HEIGHT_CM 3.0
#define QTG_FOOTLOCK_SPEED_CM_S 400.0
#define QTG_FOOTLOCK_BLEND_FRAMES 3

/* error codes (negative returns of qtg_footlock; qtg_footlock_error gives the message) */
#define QTG_FOOTLOCK_EBADARG (-1)   /* a size, a range or an option out of its domain */
#define QTG_FOOTLOCK_ESKELETON (-2) /* parents not before children, no foot joint, a leg without knee and hip */
#define QTG_FOOTLOCK_EZERO (-3)     /* a joint quaternion of the sequence is zero */
#define QTG_FOOTLOCK_ENOMEM (-4)

/* The skeleton of the pose: the metadata entry "skeleton" ({"names", "parents", "offsets"}). Joint j has the
 * name names[j], the parent parents[j] (-1 for the root, else 0 <= parents[j] < j) and the offset from its
 * parent offsets[3 j .. 3 j + 2] (cm). Foot joints are those whose name contains "foot", "toe" or "ankle"
 * (ASCII, case-insensitive). */
typedef struct {
  int joints;
  const char* const* names;
  const int* parents;
  const double* offsets;
} qtg_skeleton;

typedef struct {
  double frame_time;   /* dt (s): 1 / the metadata's "frame_rate" */
  double height_cm;    /* a foot joint within this of its lowest height over the sequence may be planted */
  double speed_cm_s;   /* ... when slower than this horizontally */
  int blend_frames;    /* n of the blends into and out of a pin, >= 1 */
  int up;              /* index of the vertical axis (1: y up) */
} qtg_footlock_options;

/* The defaults of spec/qtg.md 7.5 at `frame_rate` frames per second. */
qtg_footlock_options qtg_footlock_defaults(double frame_rate);

/* Pin the planted feet of frames [start, stop) of `sequence` (frames * (3 + 4 J) doubles, changed in place).
 * 1 <= start < stop <= frames - 1. Returns the number of frames changed (>= 0; each changed frame carries unit
 * quaternions, every other frame is left bit for bit), or a negative QTG_FOOTLOCK_E* code (sequence unchanged). */
int qtg_footlock(const qtg_skeleton* skeleton, const qtg_footlock_options* options, double* sequence, int frames,
                 int start, int stop);

/* The message of a negative return of qtg_footlock. */
const char* qtg_footlock_error(int code);

/* A skeleton parsed from the JSON text of the metadata entry "skeleton" as the exporter writes it (keys
 * "names", "parents", "offsets"; strings without escapes other than \" and \\). Returns 0, or -1 when the text
 * does not hold three arrays of the same length. Free with qtg_skeleton_free. */
int qtg_skeleton_from_json(const char* json, qtg_skeleton* out);
void qtg_skeleton_free(qtg_skeleton* skeleton);

#ifdef __cplusplus
}
#endif

#endif /* QTG_FOOTLOCK_H */
