/* Foot locking of a generated QTG transition (spec/qtg.md 7.5); interface and contract in qtg_footlock.h.
 *
 * The steps, numbered as in the spec and in refimpl/protocols/transition_footlock.py (its NumPy oracle; the tests
 * compare the two on real frames, tests/test_c_footlock.py):
 *   1. legs: ankle = a foot joint whose parent is not one, knee = its parent, hip = the knee's parent;
 *   2. contacts: a leg is planted where one of its foot joints is low and slow;
 *   3. pins: each run of planted frames is pinned at one frame, with a weight per frame;
 *   4. targets: the ankle's horizontal position and the foot's world rotation blended towards the pins;
 *   5. two-bone IK: new local rotations of hip, knee and ankle.
 * Shapes in comments: F frames, J joints, P = 3 + 4 J.
 */
#include "qtg_footlock.h"

#include <ctype.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#define TINY 1e-12

/* ---------------------------------------------------------------- small vector and quaternion helpers */

static double dot3(const double* a, const double* b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
static double norm3(const double* a) { return sqrt(dot3(a, a)); }

static void cross3(const double* a, const double* b, double* out) {
  const double x = a[1] * b[2] - a[2] * b[1], y = a[2] * b[0] - a[0] * b[2], z = a[0] * b[1] - a[1] * b[0];
  out[0] = x, out[1] = y, out[2] = z;
}

/* Hamilton product q (x) r, quaternions (w, x, y, z) */
static void qmul(const double* q, const double* r, double* out) {
  const double w = q[0] * r[0] - q[1] * r[1] - q[2] * r[2] - q[3] * r[3];
  const double x = q[0] * r[1] + q[1] * r[0] + q[2] * r[3] - q[3] * r[2];
  const double y = q[0] * r[2] - q[1] * r[3] + q[2] * r[0] + q[3] * r[1];
  const double z = q[0] * r[3] + q[1] * r[2] - q[2] * r[1] + q[3] * r[0];
  out[0] = w, out[1] = x, out[2] = y, out[3] = z;
}

static void qconj(const double* q, double* out) { out[0] = q[0], out[1] = -q[1], out[2] = -q[2], out[3] = -q[3]; }

/* v + 2 (w (u x v) + u x (u x v)), u = (x, y, z) of q */
static void qrotate(const double* q, const double* v, double* out) {
  double uv[3], uuv[3];
  cross3(q + 1, v, uv);
  cross3(q + 1, uv, uuv);
  for (int i = 0; i < 3; ++i) out[i] = v[i] + 2.0 * (q[0] * uv[i] + uuv[i]);
}

/* unit quaternion of the rotation vector v = theta n: (cos(theta/2), sin(theta/2)/theta v) */
static void quat_from_rotation_vector(const double* v, double* out) {
  const double half = 0.5 * norm3(v);
  const double s = half < 1e-8 ? 0.5 : 0.5 * sin(half) / half;
  out[0] = cos(half), out[1] = s * v[0], out[2] = s * v[1], out[3] = s * v[2];
}

/* +-1 making conj(q0) (x) (+-q1) canonical: its first non-zero component positive (sign of <q0, q1> away from 0) */
static double hemisphere_sign(const double* q0, const double* q1) {
  double c[4], rel[4];
  qconj(q0, c);
  qmul(c, q1, rel);
  for (int i = 0; i < 4; ++i)
    if (rel[i] != 0.0) return rel[i] < 0.0 ? -1.0 : 1.0;
  return 1.0;
}

static double smooth(double u) {
  u = u < 0.0 ? 0.0 : (u > 1.0 ? 1.0 : u);
  return u * u * (3.0 - 2.0 * u);
}

static int is_foot_name(const char* name) {
  static const char* const words[3] = {"foot", "toe", "ankle"};
  char low[256];
  size_t n = 0;
  for (; name[n] != '\0' && n + 1 < sizeof low; ++n) low[n] = (char)tolower((unsigned char)name[n]);
  low[n] = '\0';
  for (int i = 0; i < 3; ++i)
    if (strstr(low, words[i]) != NULL) return 1;
  return 0;
}

/* ---------------------------------------------------------------- step 5: two-bone IK */

/* a unit vector perpendicular to v: v x e, e the axis least aligned with v (the first on ties) */
static void perpendicular(const double* v, double* out) {
  int k = 0;
  for (int i = 1; i < 3; ++i)
    if (fabs(v[i]) < fabs(v[k])) k = i;
  double e[3] = {0.0, 0.0, 0.0};
  e[k] = 1.0;
  cross3(v, e, out);
  const double n = fmax(norm3(out), TINY);
  for (int i = 0; i < 3; ++i) out[i] /= n;
}

/* world-frame rotations rot_hip, rot_knee moving the ankle of hip -> knee -> ankle onto target (hint may be NULL) */
static void two_bone_ik(const double* hip, const double* knee, const double* ankle, const double* target,
                        const double* hint, double* rot_hip, double* rot_knee) {
  double a[3], b[3], n[3], minus_a[3], ab[3], v[3], u[3], rb[3], axis[3], rv[3];
  for (int i = 0; i < 3; ++i) a[i] = knee[i] - hip[i], b[i] = ankle[i] - knee[i], minus_a[i] = -a[i];
  const double l1 = norm3(a), l2 = norm3(b);
  cross3(a, b, n);
  if (hint != NULL && norm3(n) <= 1e-9 * l1 * l2) cross3(hint, a, n);
  if (norm3(n) <= 1e-9 * l1 * l2) perpendicular(a, n);
  const double nn = fmax(norm3(n), TINY);
  for (int i = 0; i < 3; ++i) n[i] /= nn;
  for (int i = 0; i < 3; ++i) v[i] = target[i] - hip[i];
  double d = norm3(v);
  const double lo = fabs(l1 - l2), hi = l1 + l2;
  d = d < lo ? lo : (d > hi ? hi : d);
  const double want = 2.0 * atan2(sqrt(fmax((d + l2 - l1) * (d + l1 - l2), 0.0)),
                                  sqrt(fmax((l1 + l2 + d) * (l1 + l2 - d), 0.0)));
  cross3(minus_a, b, ab);
  const double now = atan2(norm3(ab), dot3(minus_a, b));
  for (int i = 0; i < 3; ++i) rv[i] = n[i] * (now - want);
  quat_from_rotation_vector(rv, rot_knee); /* turning b about n opens the knee */
  qrotate(rot_knee, b, rb);
  for (int i = 0; i < 3; ++i) u[i] = a[i] + rb[i]; /* hip -> new ankle */
  cross3(u, v, axis);
  const double s = norm3(axis);
  if (s <= 1e-12 * norm3(u) * norm3(v)) {
    memcpy(axis, n, sizeof axis);
  } else {
    const double sc = fmax(s, TINY);
    for (int i = 0; i < 3; ++i) axis[i] /= sc;
  }
  const double angle = atan2(s, dot3(u, v));
  for (int i = 0; i < 3; ++i) rv[i] = axis[i] * angle;
  quat_from_rotation_vector(rv, rot_hip);
}

/* ---------------------------------------------------------------- steps 1-4 on one leg */

typedef struct {
  int hip, knee, ankle, toe; /* toe: the ankle's first foot child (-1: none), the straight leg's hint */
} leg_t;

typedef struct {
  int F, J, start, stop;
  const qtg_footlock_options* o;
  const double *pos, *world; /* (F, J, 3), (F, J, 4) of the input */
  double* q_new;             /* (F, J, 4) */
  unsigned char *changed, *contact, *in_leg;
  double *w, *wsum, *pin_pos, *pin_rot; /* (F) each, (F, 3), (F, 4) */
} work_t;

/* step 2: contact[k] of the leg's foot joints (in_leg[j]) */
static void detect_contacts(work_t* s) {
  const int F = s->F, J = s->J, up = s->o->up;
  memset(s->contact, 0, (size_t)F);
  for (int j = 0; j < J; ++j) {
    if (!s->in_leg[j]) continue;
    double low = INFINITY;
    for (int k = 0; k < F; ++k) low = fmin(low, s->pos[(k * J + j) * 3 + up]);
    for (int k = 0; k < F; ++k) {
      double step[2]; /* horizontal speed of the steps into and out of frame k */
      for (int t = 0; t < 2; ++t) {
        int k0 = k - 1 + t;
        if (k0 < 0) k0 = 0; /* first frame: the step out, twice; last frame: the step in */
        if (k0 > F - 2) k0 = F - 2;
        double h = 0.0;
        for (int i = 0; i < 3; ++i) {
          if (i == up) continue;
          const double dx = s->pos[((k0 + 1) * J + j) * 3 + i] - s->pos[(k0 * J + j) * 3 + i];
          h += dx * dx;
        }
        step[t] = sqrt(h) / s->o->frame_time;
      }
      const double v = (k == 0) ? step[1] : (k == F - 1) ? step[0] : 0.5 * (step[1] + step[0]);
      if (s->pos[(k * J + j) * 3 + up] - low < s->o->height_cm && v < s->o->speed_cm_s) s->contact[k] = 1;
    }
  }
}

/* step 3: the weights w[k] of the run [rs, re] (inclusive); returns its pinned frame, or -1 when w is all 0 */
static int run_weights(work_t* s, int rs, int re) {
  const int n = s->o->blend_frames, start = s->start, stop = s->stop;
  int p, s_h, e_h;
  if (rs < start) {
    p = start - 1, s_h = start, e_h = re < stop - 2 - n ? re : stop - 2 - n;
  } else if (re >= stop) {
    p = stop, s_h = rs > start + n ? rs : start + n, e_h = stop - 1;
  } else {
    p = rs, s_h = rs, e_h = re < stop - 2 - n ? re : stop - 2 - n;
  }
  const int m = (p == stop) ? (n < s_h - start ? n : s_h - start) : 0;
  int any = 0;
  for (int k = 0; k < s->F; ++k) {
    double w = 0.0;
    if (k >= start && k < stop)
      w = fmin(smooth((double)(k - s_h + m + 1) / (double)(m + 1)), smooth((double)(e_h + n + 1 - k) / (double)(n + 1)));
    s->w[k] = w;
    any |= w > 0.0;
  }
  return any ? p : -1;
}

/* steps 3-4: accumulate every run's pin into wsum, pin_pos, pin_rot */
static void accumulate_pins(work_t* s, const leg_t* leg) {
  const int F = s->F, J = s->J, a = leg->ankle;
  memset(s->wsum, 0, sizeof(double) * (size_t)F);
  memset(s->pin_pos, 0, sizeof(double) * 3 * (size_t)F);
  memset(s->pin_rot, 0, sizeof(double) * 4 * (size_t)F);
  for (int k = 0; k < F; ++k) {
    if (!s->contact[k] || (k > 0 && s->contact[k - 1])) continue; /* k: the first frame of a run */
    int e = k;
    while (e + 1 < F && s->contact[e + 1]) ++e;
    const int p = run_weights(s, k, e);
    if (p < 0) continue;
    const double *xp = s->pos + (p * J + a) * 3, *qp = s->world + (p * J + a) * 4;
    for (int f = 0; f < F; ++f) {
      const double w = s->w[f];
      if (w == 0.0) continue;
      const double sg = hemisphere_sign(s->world + (f * J + a) * 4, qp);
      s->wsum[f] += w;
      for (int i = 0; i < 3; ++i) s->pin_pos[f * 3 + i] += w * xp[i];
      for (int i = 0; i < 4; ++i) s->pin_rot[f * 4 + i] += w * sg * qp[i];
    }
  }
}

/* steps 4-5 at frame k of one leg: new locals of hip, knee and ankle into q_new */
static void solve_frame(work_t* s, const leg_t* leg, const int* parents, int k) {
  const int J = s->J, up = s->o->up;
  const double* P = s->pos + k * J * 3;
  const double* Q = s->world + k * J * 4;
  const double W = s->wsum[k], c = fmax(1.0, W), keep = 1.0 - W / c;
  const double* xa = P + leg->ankle * 3;
  double target[3], qf[4], hint[3], rh[4], rk[4], t1[4], t2[4], t3[4];
  for (int i = 0; i < 3; ++i) target[i] = keep * xa[i] + s->pin_pos[k * 3 + i] / c;
  target[up] = xa[up]; /* the pin holds the horizontal position; the height is the motion's */
  for (int i = 0; i < 4; ++i) qf[i] = keep * Q[leg->ankle * 4 + i] + s->pin_rot[k * 4 + i] / c;
  const double qn = sqrt(qf[0] * qf[0] + qf[1] * qf[1] + qf[2] * qf[2] + qf[3] * qf[3]);
  for (int i = 0; i < 4; ++i) qf[i] /= qn;
  if (leg->toe >= 0)
    for (int i = 0; i < 3; ++i) hint[i] = P[leg->toe * 3 + i] - xa[i];
  two_bone_ik(P + leg->hip * 3, P + leg->knee * 3, xa, target, leg->toe >= 0 ? hint : NULL, rh, rk);
  const double *w_par = Q + parents[leg->hip] * 4, *w_hip = Q + leg->hip * 4, *w_knee = Q + leg->knee * 4;
  double* out = s->q_new + k * J * 4;
  qmul(rh, w_hip, t1); /* hip: conj(Q_parent) (x) r_hip (x) Q_hip */
  qconj(w_par, t2);
  qmul(t2, t1, out + leg->hip * 4);
  qmul(rk, w_knee, t1); /* knee: conj(Q_hip) (x) r_knee (x) Q_knee */
  qconj(w_hip, t2);
  qmul(t2, t1, out + leg->knee * 4);
  qmul(rh, t1, t3); /* the knee's new world rotation r_hip (x) r_knee (x) Q_knee */
  qconj(t3, t2);
  qmul(t2, qf, out + leg->ankle * 4); /* ankle: its world rotation becomes the foot's target */
  s->changed[k] = 1;
}

/* ---------------------------------------------------------------- the sequence */

/* step 1: legs[] of the skeleton; returns their count, or QTG_FOOTLOCK_ESKELETON */
static int leg_chains(const qtg_skeleton* sk, leg_t* legs, unsigned char* foot) {
  const int J = sk->joints;
  int count = 0;
  for (int j = 0; j < J; ++j) foot[j] = (unsigned char)is_foot_name(sk->names[j]);
  for (int a = 0; a < J; ++a) {
    if (!foot[a] || (sk->parents[a] >= 0 && foot[sk->parents[a]])) continue;
    const int knee = sk->parents[a], hip = knee > 0 ? sk->parents[knee] : -1;
    if (hip <= 0) return QTG_FOOTLOCK_ESKELETON; /* a knee and a hip below the root */
    int toe = -1;
    for (int c = a + 1; c < J && toe < 0; ++c)
      if (sk->parents[c] == a && foot[c]) toe = c;
    legs[count++] = (leg_t){hip, knee, a, toe};
  }
  return count > 0 ? count : QTG_FOOTLOCK_ESKELETON;
}

/* q (F, J, 4) normalised, world rotations and FK positions of the sequence; QTG_FOOTLOCK_EZERO on a zero quaternion */
static int kinematics(const qtg_skeleton* sk, const double* seq, int F, double* q, double* world, double* pos) {
  const int J = sk->joints, P = 3 + 4 * J;
  for (int k = 0; k < F; ++k) {
    for (int j = 0; j < J; ++j) {
      const double* src = seq + k * P + 3 + 4 * j;
      double* qj = q + (k * J + j) * 4;
      const double n = sqrt(src[0] * src[0] + src[1] * src[1] + src[2] * src[2] + src[3] * src[3]);
      if (!(n >= TINY)) return QTG_FOOTLOCK_EZERO;
      for (int i = 0; i < 4; ++i) qj[i] = src[i] / n;
      double* wj = world + (k * J + j) * 4;
      double* xj = pos + (k * J + j) * 3;
      const int p = sk->parents[j];
      if (p < 0) {
        memcpy(wj, qj, 4 * sizeof *wj);
        memcpy(xj, seq + k * P, 3 * sizeof *xj);
      } else {
        double r[3];
        qrotate(world + (k * J + p) * 4, sk->offsets + 3 * j, r);
        for (int i = 0; i < 3; ++i) xj[i] = pos[(k * J + p) * 3 + i] + r[i];
        qmul(world + (k * J + p) * 4, qj, wj);
      }
    }
  }
  return 0;
}

static int check_arguments(const qtg_skeleton* sk, const qtg_footlock_options* o, const double* seq, int F,
                           int start, int stop) {
  if (sk == NULL || o == NULL || seq == NULL || sk->joints < 1 || sk->names == NULL || sk->parents == NULL ||
      sk->offsets == NULL)
    return QTG_FOOTLOCK_EBADARG;
  if (!(1 <= start && start < stop && stop <= F - 1)) return QTG_FOOTLOCK_EBADARG;
  if (!(o->frame_time > 0.0 && isfinite(o->frame_time)) || o->blend_frames < 1 || o->up < 0 || o->up > 2 ||
      isnan(o->height_cm) || isnan(o->speed_cm_s))
    return QTG_FOOTLOCK_EBADARG;
  for (int j = 0; j < sk->joints; ++j)
    if (sk->names[j] == NULL || (j == 0 ? sk->parents[j] != -1 : (sk->parents[j] < 0 || sk->parents[j] >= j)))
      return QTG_FOOTLOCK_ESKELETON;
  return 0;
}

int qtg_footlock(const qtg_skeleton* sk, const qtg_footlock_options* o, double* seq, int F, int start, int stop) {
  int rc = check_arguments(sk, o, seq, F, start, stop);
  if (rc < 0) return rc;
  const int J = sk->joints, P = 3 + 4 * J;
  const size_t fj = (size_t)F * (size_t)J;
  work_t s = {F, J, start, stop, o, NULL, NULL, NULL, NULL, NULL, NULL, NULL, NULL, NULL, NULL};
  double* q = malloc(sizeof(double) * 4 * fj);
  double* world = malloc(sizeof(double) * 4 * fj);
  double* pos = malloc(sizeof(double) * 3 * fj);
  s.q_new = malloc(sizeof(double) * 4 * fj);
  double* per_frame = malloc(sizeof(double) * 9 * (size_t)F); /* w, wsum, pin_pos (3), pin_rot (4) */
  unsigned char* flags = malloc(2 * (size_t)F + 2 * (size_t)J);  /* changed, contact, in_leg, foot */
  leg_t* legs = malloc(sizeof(leg_t) * (size_t)J);
  if (!q || !world || !pos || !s.q_new || !per_frame || !flags || !legs) {
    rc = QTG_FOOTLOCK_ENOMEM;
    goto done;
  }
  s.pos = pos, s.world = world, s.w = per_frame, s.wsum = per_frame + F, s.pin_pos = per_frame + 2 * F;
  s.pin_rot = per_frame + 5 * F, s.changed = flags, s.contact = flags + F, s.in_leg = flags + 2 * F;
  unsigned char* foot = flags + 2 * F + J;
  const int n_legs = rc = leg_chains(sk, legs, foot);
  if (rc < 0) goto done;
  rc = kinematics(sk, seq, F, q, world, pos);
  if (rc < 0) goto done;
  memcpy(s.q_new, q, sizeof(double) * 4 * fj);
  memset(s.changed, 0, (size_t)F);
  for (int l = 0; l < n_legs; ++l) {
    memset(s.in_leg, 0, (size_t)J); /* the ankle and the foot joints below it */
    s.in_leg[legs[l].ankle] = 1;
    for (int j = legs[l].ankle + 1; j < J; ++j) s.in_leg[j] = foot[j] && s.in_leg[sk->parents[j]];
    detect_contacts(&s);
    accumulate_pins(&s, &legs[l]);
    for (int k = start; k < stop; ++k)
      if (s.wsum[k] > 0.0) solve_frame(&s, &legs[l], sk->parents, k);
  }
  rc = 0;
  for (int k = 0; k < F; ++k) { /* changed frames: the root as it was, every joint's unit quaternion */
    if (!s.changed[k]) continue;
    memcpy(seq + k * P + 3, s.q_new + (size_t)k * J * 4, sizeof(double) * 4 * (size_t)J);
    ++rc;
  }
done:
  free(q), free(world), free(pos), free(s.q_new), free(per_frame), free(flags), free(legs);
  return rc;
}

qtg_footlock_options qtg_footlock_defaults(double frame_rate) {
  qtg_footlock_options o = {1.0 / frame_rate, QTG_FOOTLOCK_HEIGHT_CM, QTG_FOOTLOCK_SPEED_CM_S,
                            QTG_FOOTLOCK_BLEND_FRAMES, 1};
  return o;
}

const char* qtg_footlock_error(int code) {
  switch (code) {
    case QTG_FOOTLOCK_EBADARG: return "footlock: expected 1 <= start < stop <= frames - 1 and valid options";
    case QTG_FOOTLOCK_ESKELETON:
      return "footlock: the skeleton needs parents before children and feet (foot/toe/ankle) with knee and hip";
    case QTG_FOOTLOCK_EZERO: return "footlock: a joint quaternion is zero";
    case QTG_FOOTLOCK_ENOMEM: return "footlock: out of memory";
    default: return code < 0 ? "footlock: unknown error" : "ok";
  }
}

/* ---------------------------------------------------------------- the metadata entry "skeleton" */

/* the array after "key": in json, or NULL */
static const char* array_of(const char* json, const char* key) {
  char quoted[32];
  const size_t n = strlen(key);
  if (n + 3 > sizeof quoted) return NULL;
  quoted[0] = '"';
  memcpy(quoted + 1, key, n);
  quoted[n + 1] = '"', quoted[n + 2] = '\0';
  const char* at = strstr(json, quoted);
  if (at == NULL) return NULL;
  at += n + 2;
  while (*at == ' ' || *at == ':' || *at == '\n' || *at == '\t' || *at == '\r') ++at;
  return *at == '[' ? at + 1 : NULL;
}

static void free_names(char** names, int count) {
  for (int i = 0; i < count; ++i) free(names[i]);
  free(names);
}

/* the strings of the array at `at` into *names (allocated); returns their count, or -1 (nothing allocated) */
static int parse_names(const char* at, char*** names) {
  int count = 0, cap = 0;
  char** list = NULL;
  *names = NULL;
  while (at != NULL && *at != '\0' && *at != ']') {
    if (*at != '"') {
      ++at;
      continue;
    }
    const char* end = ++at;
    size_t len = 0;
    for (; *end != '\0' && *end != '"'; ++end, ++len)
      if (*end == '\\' && end[1] != '\0') ++end;
    char* name = *end == '"' ? malloc(len + 1) : NULL;
    if (count == cap && name != NULL) {
      cap = cap ? 2 * cap : 32;
      char** grown = realloc(list, sizeof(char*) * (size_t)cap);
      if (grown == NULL) free(name), name = NULL;
      else list = grown;
    }
    if (name == NULL) {
      free_names(list, count);
      return -1;
    }
    for (size_t i = 0; at < end; ++at) {
      if (*at == '\\') ++at;
      name[i++] = *at;
    }
    name[len] = '\0';
    list[count++] = name;
    at = end + 1;
  }
  if (at == NULL || *at != ']') {
    free_names(list, count);
    return -1;
  }
  *names = list;
  return count;
}

/* `count` numbers of the (possibly nested) array at `at`; returns how many were read before its closing ] */
static int parse_numbers(const char* at, double* out, int count) {
  int read = 0, depth = 1;
  while (at != NULL && *at != '\0' && depth > 0) {
    if (*at == '[') {
      ++depth, ++at;
    } else if (*at == ']') {
      --depth, ++at;
    } else if (*at == '-' || *at == '+' || *at == '.' || isdigit((unsigned char)*at)) {
      char* end;
      const double v = strtod(at, &end);
      if (end == at) return -1;
      if (read < count) out[read] = v;
      ++read, at = end;
    } else {
      ++at;
    }
  }
  return depth == 0 ? read : -1;
}

int qtg_skeleton_from_json(const char* json, qtg_skeleton* out) {
  memset(out, 0, sizeof *out);
  if (json == NULL) return -1;
  char** names = NULL;
  const int J = parse_names(array_of(json, "names"), &names);
  int* parents = J > 0 ? malloc(sizeof(int) * (size_t)J) : NULL;
  double* offsets = J > 0 ? malloc(sizeof(double) * 3 * (size_t)J) : NULL;
  double* tmp = J > 0 ? malloc(sizeof(double) * (size_t)J) : NULL;
  int ok = J > 0 && parents && offsets && tmp && parse_numbers(array_of(json, "parents"), tmp, J) == J &&
           parse_numbers(array_of(json, "offsets"), offsets, 3 * J) == 3 * J;
  for (int j = 0; ok && j < J; ++j) {
    parents[j] = (int)tmp[j];
    ok = (double)parents[j] == tmp[j];
  }
  free(tmp);
  out->joints = J > 0 ? J : 0, out->names = (const char* const*)names, out->parents = parents;
  out->offsets = offsets;
  if (!ok) {
    qtg_skeleton_free(out);
    return -1;
  }
  return 0;
}

void qtg_skeleton_free(qtg_skeleton* sk) {
  if (sk->names != NULL)
    for (int j = 0; j < sk->joints; ++j) free((void*)sk->names[j]);
  free((void*)sk->names), free((void*)sk->parents), free((void*)sk->offsets);
  memset(sk, 0, sizeof *sk);
}
