/*
 * kinecal.models._ckernel: the calibration model's forward kinematics and exact parameter
 * Jacobian in compiled code, several poses at a time.
 *
 * It computes what CalibrationModel.evaluate computes with numpy (kinecal/models/
 * _numpy_forward.py and _numpy_jacobian.py; the math is in docs/theory.md and the paper's
 * Eq. 7-10, 16-26, the Jacobian of Eq. 28) for all-revolute arms:
 * the undeflected chain, the load and link torques (Eq. 21, 25), the deflections
 * (Eq. 22, 24, 26), the deflected chain, and every Jacobian column, including the
 * dependence of the torques on the geometry (the torque adjoint of _compliance.py).
 * kinecal/models/_kernel.py packs the model's definition (ModelDefinition,
 * kinecal/models/_definition.py) into two tables (int64 and float64) whose
 * layout is given by the header below; FIELDS exports its names, in order, and the
 * Python side does not use a build whose names differ from its own (a stale build).
 *
 * Every per-pose quantity is a vector of LANES poses (GCC/Clang vector extensions; one
 * pose with other compilers), so each arithmetic operation serves several poses, as
 * numpy's do, without numpy's temporaries. Two lanes are the width of the baseline SIMD
 * of x86-64 (SSE2) and ARM64 (NEON); four lanes built for baseline x86-64 ran 2x slower
 * (7 against 4 ms for the full model's Jacobian on 6855 poses). With GCC on x86-64 the
 * kernel is also compiled for four lanes of AVX2 and eight of AVX-512F, and the widest
 * that the CPU runs is chosen when the module loads (lanes()): the full model's Jacobian
 * of 2000 poses took 0.76 ms on two lanes, 0.50 on four and 0.43 on eight (one AMD EPYC
 * core). Each pose's arithmetic is the same operations in the same order on every width:
 * the same numbers to the last bit. setup.py turns off fused multiply-adds, so that
 * every build rounds alike.
 *
 * Conventions: a 3-vector is vd[3]; a frame's rotation is stored by columns,
 * R[a][comp] = component comp of axis a (x, y, z), as the numpy ChainFrames.cols.
 * Per-pose inputs are pose-last (n, N) or pose-first (N, 3), as documented in evaluate();
 * the Jacobian is parameter-major (P + K, c, N), the numpy model's layout.
 *
 * The function releases the interpreter lock, so callers may run disjoint pose ranges
 * [k0, k1) on several threads.
 *
 * gram() forms the products of the normal equations (J^T J, J^T r) of such a Jacobian
 * for kinecal/identification/_normal.py, where the CPU has AVX (see there).
 *
 * Only the stable ABI of Python 3.11 is used (Py_LIMITED_API; setup.py sets it too), so
 * one build (a wheel tagged abi3) serves every CPython from 3.11 on.
 */
#ifndef Py_LIMITED_API
#define Py_LIMITED_API 0x030B0000
#endif
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#define NMAX 16             /* joints */
#define CMAX 6              /* output components: position, then rotation */
#define PMAX 256            /* link products */
#define LMAX (3 + 4 * NMAX) /* link parameters */

#ifndef KC_SUFFIX /* the module's tables and the kernel's widths (this file again) */

/* Integer header: the names exported as FIELDS, in this order. */
enum {
    H_N,          /* joints n */
    H_SETS,       /* user frames S */
    H_MARKERS,    /* cam frames M */
    H_C,          /* output rows: 3 (position) or 6 (and rotation) */
    H_P,          /* parameters */
    H_K,          /* product columns to write after the P columns (0 unless asked) */
    H_NPROD,      /* link products (lambda*_j s_k pairs) of the model */
    H_JACOBIAN,   /* 1: write the Jacobian */
    H_CAM_ROT,    /* 1: the cam rotation is identified */
    H_LOAD,       /* 1: payload compliance lambda* */
    H_LINK,       /* lumped link model: 0 none, 1 paper, 2 rfcm */
    H_SHOULDER,   /* 1-based joints and frame of the lumped model */
    H_ELBOW,
    H_WRIST,
    H_NBODIES,    /* bodies of the general link model */
    H_NLINK,      /* link parameters (lumped first, then 4 per body) */
    H_NNTM,       /* joints with a Fourier series */
    H_NB,         /* basis functions per series */
    H_NTM_START,  /* first NTM column */
    H_LAM_START,  /* first lambda* column */
    H_LINK_START, /* first link column */
    H_I_ROWIDX,   /* int offsets: (n, 5) row parameter columns, -1 = none */
    H_I_CAMIDX,   /* (M, 6) cam columns x y z r w p, -1 = none */
    H_I_BASEIDX,  /* (S, 6) user frame columns */
    H_I_NTMJ,     /* (n_ntm,) 0-based joints */
    H_I_BODIES,   /* (n_bodies,) DH frame of each body */
    H_I_PROD,     /* (n_prod, 5) joint (0-based), link column, kind, frame, axis */
    H_R_ROWS,     /* real offsets: (n, 8) cos/sin offset, d, a, cos/sin alpha, cos/sin beta */
    H_R_BASE,     /* (S, 24) R (row-major), t, gravity, Euler axes r w p (by columns) */
    H_R_CAM,      /* (M, 21) R (row-major), t, Euler axes r w p (by columns) */
    H_R_LAM,      /* (n,) lambda* */
    H_R_LINK,     /* (n_link,) link parameters */
    H_R_NTM,      /* (n_ntm, nb) Fourier coefficients */
    H_R_XSIGN,    /* (1,) sign of the shoulder row's a */
    H_COUNT
};

static const char *const FIELDS[H_COUNT] = {
    "n", "sets", "markers", "c", "P", "K", "n_products", "jacobian", "cam_rotation",
    "load", "link", "shoulder", "elbow", "wrist", "n_bodies", "n_link", "n_ntm", "nb",
    "ntm_start", "lam_start", "link_start", "i_row_idx", "i_cam_idx", "i_base_idx",
    "i_ntm_joints", "i_bodies", "i_products", "r_rows", "r_base", "r_cam", "r_lam",
    "r_link", "r_ntm", "r_xsign",
};

/* Kinds of a link product's torque basis value (the column of link_T it reads). */
enum { PK_XHAT = 0, PK_UHAT = 1, PK_MASS = 2, PK_MOMENT = 3 };
/* Row parameters, the columns of the numpy row table. */
enum { R_OFF = 0, R_D, R_A, R_ALPHA, R_BETA };

typedef struct {
    const long long *h; /* header, then the integer tables */
    const double *r;    /* real tables */
    Py_ssize_t N;       /* poses in the arrays (the stride of pose-last rows) */
    /* per-pose inputs */
    const double *thc, *cq, *sq, *basis, *p_cam, *load_scale;
    const long long *set_index, *marker_index;
    /* outputs */
    double *p_user, *R_uc, *theta, *J;
} Args;

/* ------------------------------------------------------------------ the kernel's widths */
/* The kernel (below, where KC_SUFFIX is defined) is compiled once per vector width: this
   file includes itself with LANES, KC_TARGET (the instruction set of its functions) and
   KC_SUFFIX (appended to its names) set. */
#define KC_CAT_(a, b) a##b
#define KC_CAT(a, b) KC_CAT_(a, b)
#define KC_NAME(name) KC_CAT(name, KC_SUFFIX)

typedef int (*RunBlocks)(const Args *in, Py_ssize_t k0, Py_ssize_t k1);

#if (defined(__GNUC__) || defined(__clang__)) && !defined(KINECAL_SCALAR_KERNEL)
#define LANES 2
#define KC_TARGET
#define KC_SUFFIX _2
#include "_ckernel.c"
#define BASE_LANES 2
#define BASE_RUN run_blocks_2
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__)
#define HAVE_WIDE 1
#define LANES 4
#define KC_TARGET __attribute__((target("avx2")))
#define KC_SUFFIX _4
#include "_ckernel.c"
#define LANES 8
#define KC_TARGET __attribute__((target("avx512f")))
#define KC_SUFFIX _8
#include "_ckernel.c"
#endif
#else /* one pose per operation: other compilers, or -DKINECAL_SCALAR_KERNEL */
#define LANES 1
#define KC_TARGET
#define KC_SUFFIX _1
#include "_ckernel.c"
#define BASE_LANES 1
#define BASE_RUN run_blocks_1
#endif

/* The widths this build has, narrowest first, and the one in use (lanes()). */
typedef struct {
    int lanes;
    RunBlocks run;
    const char *cpu; /* the CPU feature it needs (NULL: none) */
} Width;

static const Width widths[] = {
    {BASE_LANES, BASE_RUN, NULL},
#ifdef HAVE_WIDE
    {4, run_blocks_4, "avx2"},
    {8, run_blocks_8, "avx512f"},
#endif
};
#define N_WIDTHS ((int)(sizeof widths / sizeof widths[0]))
static int width_ok[N_WIDTHS]; /* this CPU runs it (set when the module loads) */
static int width = 0;          /* index of the width in use */
#endif

#ifdef KC_SUFFIX /* one width of the kernel, included by the code above */
/* ================================================================== the kernel */
/* One width of the kernel (included by the code above with LANES, KC_TARGET and
   KC_SUFFIX set): its names get the suffix, so that the widths live side by side. */
#define vd KC_NAME(vd)
#define vm KC_NAME(vm)
#define vload KC_NAME(vload)
#define vstore KC_NAME(vstore)
#define vsplat KC_NAME(vsplat)
#define vsel KC_NAME(vsel)
#define vsqrt KC_NAME(vsqrt)
#define gather KC_NAME(gather)
#define cross KC_NAME(cross)
#define dot KC_NAME(dot)
#define scale3 KC_NAME(scale3)
#define shift KC_NAME(shift)
#define Chain KC_NAME(Chain)
#define chain KC_NAME(chain)
#define Adjoint KC_NAME(Adjoint)
#define add_term KC_NAME(add_term)
#define mat_apply KC_NAME(mat_apply)
#define mat_apply_add KC_NAME(mat_apply_add)
#define du_terms KC_NAME(du_terms)
#define block KC_NAME(block)
#define run_full KC_NAME(run_full)
#define run_blocks KC_NAME(run_blocks)

#if LANES > 1
typedef double vd __attribute__((vector_size(LANES * sizeof(double))));
typedef long long vm __attribute__((vector_size(LANES * sizeof(double)))); /* lane masks */
#define LANE(v, l) ((v)[l])
#define INLINE static inline __attribute__((always_inline)) KC_TARGET
#else
typedef double vd;
typedef long long vm;
#define LANE(v, l) (v)
#ifdef _MSC_VER
#define INLINE static __forceinline
#else
#define INLINE static inline
#endif
#endif

/* ------------------------------------------------------------------ lane helpers */
INLINE vd vload(const double *p)
{
    vd v;
    memcpy(&v, p, sizeof v);
    return v;
}

INLINE void vstore(double *p, vd v) { memcpy(p, &v, sizeof v); }

#if LANES > 1
INLINE vd vsplat(double x) { return (vd){0} + x; }
#else
INLINE vd vsplat(double x) { return x; }
#endif

INLINE vd vsel(vm mask, vd a, vd b) /* mask ? a : b, per lane */
{
#if LANES > 1
    return (vd)(((vm)a & mask) | ((vm)b & ~mask));
#else
    return mask ? a : b;
#endif
}

INLINE vd vsqrt(vd x)
{
    vd out = x;
    for (int l = 0; l < LANES; l++)
        LANE(out, l) = sqrt(LANE(x, l));
    return out;
}

/* Lane l of the result is table[index[l] * stride]. */
INLINE vd gather(const double *table, const long long *index, int stride)
{
    vd out = vsplat(0.0);
    for (int l = 0; l < LANES; l++)
        LANE(out, l) = table[index[l] * stride];
    return out;
}

INLINE void cross(const vd *a, const vd *b, vd *out)
{
    vd x = a[1] * b[2] - a[2] * b[1];
    vd y = a[2] * b[0] - a[0] * b[2];
    vd z = a[0] * b[1] - a[1] * b[0];
    out[0] = x;
    out[1] = y;
    out[2] = z;
}

INLINE vd dot(const vd *a, const vd *b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

INLINE void scale3(vd *v, vd s)
{
    v[0] *= s;
    v[1] *= s;
    v[2] *= s;
}

/* cos and sin of theta + delta from those of theta: the 7th-order series of cos and sin
   delta for |delta| <= 0.01 rad (exact to rounding, as models._chain.shifted_trig), the
   library functions for the lanes beyond. */
INLINE void shift(vd *c, vd *s, vd delta)
{
    vd d2 = delta * delta;
    vd cd = 1.0 - d2 * (0.5 - d2 * (1.0 / 24.0 - d2 * (1.0 / 720.0)));
    vd sd = delta * (1.0 - d2 * (1.0 / 6.0 - d2 * (1.0 / 120.0 - d2 * (1.0 / 5040.0))));
    for (int l = 0; l < LANES; l++)
        if (LANE(d2, l) > 1e-4) {
            LANE(cd, l) = cos(LANE(delta, l));
            LANE(sd, l) = sin(LANE(delta, l));
        }
    vd c0 = *c, s0 = *s;
    *c = c0 * cd - s0 * sd;
    *s = s0 * cd + c0 * sd;
}

/* ------------------------------------------------------------------ kinematics */
typedef struct {
    vd R[NMAX + 1][3][3]; /* frame k's axes, R[k][axis][comp] */
    vd o[NMAX + 1][3];    /* frame k's origin */
    vd ax[NMAX][3];       /* direction of row i's a (and its alpha axis) */
} Chain;

/* Frames of the rows Rz(theta) Tz(d) Tx(a) Rx(alpha) Ry(beta) (Eq. 10; beta of Hayati
   rows), from frame 0 as placed (models._chain.chain_frames). */
INLINE void chain(int n, const double *rows, const vd *ct, const vd *st, Chain *F)
{
    for (int i = 0; i < n; i++) {
        const double *row = rows + 8 * i;
        double d = row[2], a = row[3], ca = row[4], sa = row[5], cb = row[6], sb = row[7];
        const vd *c0 = F->R[i][0], *c1 = F->R[i][1], *c2 = F->R[i][2];
        vd *x = F->ax[i], *y = F->R[i + 1][1], *z = F->R[i + 1][2], v[3];
        for (int q = 0; q < 3; q++) {
            x[q] = c0[q] * ct[i] + c1[q] * st[i];
            v[q] = c1[q] * ct[i] - c0[q] * st[i];
            F->o[i + 1][q] = F->o[i][q] + a * x[q] + d * c2[q];
        }
        for (int q = 0; q < 3; q++) {
            y[q] = v[q] * ca + c2[q] * sa;
            z[q] = c2[q] * ca - v[q] * sa;
        }
        if (sb != 0.0 || cb != 1.0) { /* Ry(beta): x and z turn about y */
            for (int q = 0; q < 3; q++) {
                vd xq = x[q], zq = z[q];
                F->R[i + 1][0][q] = xq * cb - zq * sb;
                z[q] = xq * sb + zq * cb;
            }
        } else {
            memcpy(F->R[i + 1][0], x, sizeof(vd[3]));
        }
    }
}

/* ------------------------------------------------------------------ torque adjoint */
/* The weighted torque derivatives (_compliance.TorqueAdjoint): a term
   [f <= t] (omega . w + vel . v) on joint j adds H_j w^T to dM[t] and H_j v^T to dV[t]. */
typedef struct {
    vd H[NMAX][CMAX];
    vd dM[NMAX + 2][CMAX][3];
    vd dV[NMAX + 2][CMAX][3];
} Adjoint;

INLINE void add_term(Adjoint *A, const int c, int t, int j, const vd *w, const vd *v)
{
    if (t < 1) /* no geometric parameter moves frame 0 relative to gravity */
        return;
    for (int r = 0; r < c; r++) {
        vd h = A->H[j][r];
        for (int b = 0; b < 3; b++)
            A->dM[t][r][b] += h * w[b];
        if (v)
            for (int b = 0; b < 3; b++)
                A->dV[t][r][b] += h * v[b];
    }
}

INLINE void mat_apply(const int c, vd M[CMAX][3], const vd *w, vd *out)
{
    for (int r = 0; r < c; r++)
        out[r] = M[r][0] * w[0] + M[r][1] * w[1] + M[r][2] * w[2];
}

INLINE void mat_apply_add(const int c, vd M[CMAX][3], const vd *w, vd *out)
{
    for (int r = 0; r < c; r++)
        out[r] += M[r][0] * w[0] + M[r][1] * w[1] + M[r][2] * w[2];
}

/* Terms of scale * (du . vec) on joint j, u the direction from the elbow axis to the
   wrist centre normal to the elbow axis (_compliance._link_terms.du_terms). */
INLINE void du_terms(Adjoint *A, const int c, int j, double scale, const vd *vec,
                     const vd *u, const vd *z_el, const vd *o_wf, vd norm, int el, int wf)
{
    vd w[3], vv[3], pv[3];
    int t_free = el - 1 < wf ? el - 1 : wf;
    cross(u, vec, w);
    scale3(w, vsplat(scale));
    add_term(A, c, el - 1, j, w, NULL); /* the elbow frame turns u rigidly */
    vd vu = dot(vec, u);
    for (int q = 0; q < 3; q++)
        pv[q] = vec[q] - vu * u[q];
    vd pz = dot(pv, z_el);
    for (int q = 0; q < 3; q++)
        pv[q] = (pv[q] - pz * z_el[q]) / norm;
    cross(o_wf, pv, w);
    for (int q = 0; q < 3; q++) {
        w[q] *= scale;
        vv[q] = scale * pv[q];
    }
    add_term(A, c, wf, j, w, vv); /* the wrist centre moves, the elbow does not */
    for (int q = 0; q < 3; q++) {
        w[q] = -w[q];
        vv[q] = -vv[q];
    }
    add_term(A, c, t_free, j, w, vv);
}

/* ------------------------------------------------------------------ one block of poses */
/* Poses k .. k + LANES - 1 (all inside the arrays): forward kinematics, and with the
   header's jacobian flag every column. c is a constant of each caller. */
INLINE void block(const Args *in, Py_ssize_t k, const int c)
{
    const long long *h = in->h;
    const double *r = in->r;
    const Py_ssize_t N = in->N;
    const int n = (int)h[H_N], S = (int)h[H_SETS], M = (int)h[H_MARKERS];
    const int load = (int)h[H_LOAD], nprod = (int)h[H_NPROD], nntm = (int)h[H_NNTM];
    const int nb = (int)h[H_NB];
    const long long *row_idx = h + h[H_I_ROWIDX], *cam_idx = h + h[H_I_CAMIDX];
    const long long *base_idx = h + h[H_I_BASEIDX], *ntm_j = h + h[H_I_NTMJ];
    const long long *prod = h + h[H_I_PROD];
    const double *rows = r + h[H_R_ROWS], *lam = r + h[H_R_LAM], *slink = r + h[H_R_LINK];
    const double *base_t = r + h[H_R_BASE], *cam_t = r + h[H_R_CAM];
    const long long *sidx = in->set_index + k, *midx = in->marker_index + k;

    /* The lanes' user frames (R row-major, t, gravity) and cam frames (R, t). */
    vd Rb[9], tb[3], gv[3], Rc[9], tc[3];
    for (int e = 0; e < 9; e++) {
        Rb[e] = gather(base_t + e, sidx, 24);
        Rc[e] = gather(cam_t + e, midx, 21);
    }
    for (int q = 0; q < 3; q++) {
        tb[q] = gather(base_t + 9 + q, sidx, 24);
        gv[q] = gather(base_t + 12 + q, sidx, 24);
        tc[q] = gather(cam_t + 9 + q, midx, 21);
    }

    /* Row angles: cos/sin of C q + offset by the angle sums, then the NTM errors. */
    vd ct[NMAX], st[NMAX], th[NMAX];
    for (int i = 0; i < n; i++) {
        vd cqi = vload(in->cq + i * N + k), sqi = vload(in->sq + i * N + k);
        ct[i] = cqi * rows[8 * i] - sqi * rows[8 * i + 1];
        st[i] = sqi * rows[8 * i] + cqi * rows[8 * i + 1];
        th[i] = vload(in->thc + i * N + k);
    }
    for (int kk = 0; kk < nntm; kk++) {
        int j = (int)ntm_j[kk];
        const double *coef = r + h[H_R_NTM] + kk * nb;
        vd e = vsplat(0.0);
        for (int b = 0; b < nb; b++) /* Eq. (17) */
            e += coef[b] * vload(in->basis + (kk * nb + b) * N + k);
        shift(&ct[j], &st[j], e);
        th[j] += e;
    }

    /* The chain starts at the user frame: frame 0 is the lane's T_user_base. */
    Chain F0, F1;
    for (int a = 0; a < 3; a++) {
        for (int q = 0; q < 3; q++)
            F0.R[0][a][q] = Rb[3 * q + a];
        F0.o[0][a] = tb[a];
    }
    chain(n, rows, ct, st, &F0);

    vd p_load[3] = {vsplat(0.0), vsplat(0.0), vsplat(0.0)}, tau[NMAX], ltp[PMAX];
    vd u[3] = {vsplat(0.0), vsplat(0.0), vsplat(0.0)};
    vd norm = vsplat(1.0);
    vd ls = load ? vload(in->load_scale + k) : vsplat(1.0);
    const double xs = r[h[H_R_XSIGN]];
    const Chain *F = &F0;
    /* Every deflection is a multiple of some lambda*_j: with all of them zero (the
       kinematic stages of a calibration) the chain is not deflected and the torques
       are needed only for the Jacobian's compliance columns (adj 0). */
    int adj = 0;
    for (int j = 0; j < n && load; j++)
        adj |= lam[j] != 0.0;
    if (load && (adj || h[H_JACOBIAN])) {
        /* Load point: origin of the first marker's cam frame (Eq. 19 with Delta = 0). */
        const double *tc0 = cam_t + 9;
        for (int q = 0; q < 3; q++)
            p_load[q] = F0.o[n][q] + F0.R[n][0][q] * tc0[0] + F0.R[n][1][q] * tc0[1] +
                        F0.R[n][2][q] * tc0[2];
        for (int j = 0; j < n; j++) { /* Eq. (21): z . (r x g) = r . (g x z) */
            vd rr[3], gz[3];
            for (int q = 0; q < 3; q++)
                rr[q] = p_load[q] - F0.o[j][q];
            cross(gv, F0.R[j][2], gz);
            tau[j] = ls * dot(rr, gz);
        }
        if (h[H_LINK]) { /* u: from the elbow axis to the wrist centre, normal to it */
            int el = (int)h[H_ELBOW], wf = (int)h[H_WRIST];
            const vd *z_el = F0.R[el - 1][2];
            vd w[3];
            for (int q = 0; q < 3; q++)
                w[q] = F0.o[wf][q] - F0.o[el - 1][q];
            vd wz = dot(w, z_el);
            for (int q = 0; q < 3; q++)
                w[q] -= wz * z_el[q];
            norm = vsqrt(dot(w, w));
            for (int q = 0; q < 3; q++)
                u[q] = w[q] / norm;
        }
        /* Link torques per unit of each link parameter (Eq. 25), at the pattern only. */
        for (int p = 0; p < nprod; p++) {
            const long long *d = prod + 5 * p;
            int j = (int)d[0], kind = (int)d[2], frame = (int)d[3], axis = (int)d[4];
            vd mvec[3], mg[3];
            for (int q = 0; q < 3; q++) {
                if (kind == PK_XHAT)
                    mvec[q] = xs * F0.R[h[H_SHOULDER]][0][q];
                else if (kind == PK_UHAT)
                    mvec[q] = u[q];
                else if (kind == PK_MASS)
                    mvec[q] = F0.o[frame][q] - F0.o[j][q];
                else
                    mvec[q] = F0.R[frame][axis][q];
            }
            cross(mvec, gv, mg);
            ltp[p] = dot(F0.R[j][2], mg);
            tau[j] += slink[d[1]] * ltp[p];
        }
    }
    if (adj) {
        /* Eq. (22), (24), (26): the deflected chain. */
        for (int i = 0; i < n; i++) {
            vd defl = lam[i] * tau[i];
            th[i] += defl;
            shift(&ct[i], &st[i], defl);
        }
        memcpy(F1.R[0], F0.R[0], sizeof F1.R[0]);
        memcpy(F1.o[0], F0.o[0], sizeof F1.o[0]);
        chain(n, rows, ct, st, &F1);
        F = &F1;
    }

    /* The measured point (Eq. 6-7): p_user = T_user_flange (t_fc + R_fc p_cam). */
    double lanes[3][LANES];
    vd pc[3], p_cam_fl[3], p_u[3];
    for (int l = 0; l < LANES; l++)
        for (int q = 0; q < 3; q++)
            lanes[q][l] = in->p_cam[3 * (k + l) + q];
    for (int q = 0; q < 3; q++)
        pc[q] = vload(lanes[q]);
    for (int q = 0; q < 3; q++)
        p_cam_fl[q] = Rc[3 * q] * pc[0] + Rc[3 * q + 1] * pc[1] + Rc[3 * q + 2] * pc[2];
    const vd(*Rn)[3] = F->R[n];
    for (int q = 0; q < 3; q++)
        p_u[q] = F->o[n][q] + Rn[0][q] * (tc[0] + p_cam_fl[0]) +
                 Rn[1][q] * (tc[1] + p_cam_fl[1]) + Rn[2][q] * (tc[2] + p_cam_fl[2]);
    for (int l = 0; l < LANES; l++)
        for (int q = 0; q < 3; q++)
            in->p_user[3 * (k + l) + q] = LANE(p_u[q], l);
    for (int i = 0; i < n; i++)
        vstore(in->theta + i * N + k, th[i]);
    if (in->R_uc) { /* R_user_cam = R_user_flange R_flange_cam */
        for (int a = 0; a < 3; a++)
            for (int b = 0; b < 3; b++) {
                vd v = Rn[0][a] * Rc[b] + Rn[1][a] * Rc[3 + b] + Rn[2][a] * Rc[6 + b];
                for (int l = 0; l < LANES; l++)
                    in->R_uc[9 * (k + l) + 3 * a + b] = LANE(v, l);
            }
    }
    if (!h[H_JACOBIAN])
        return;

    /* ----------------------------------------------------- Jacobian (Eq. 28) */
    double *J = in->J;
#define PUT(col, vec)                                                                    \
    do {                                                                                 \
        double *dst_ = J + (Py_ssize_t)(col) * c * N + k;                                \
        for (int r_ = 0; r_ < c; r_++)                                                   \
            vstore(dst_ + r_ * N, (vec)[r_]);                                            \
    } while (0)

    /* d output / d theta_i (deflected chain): [z_i x (p - o_i); z_i], the columns of
       J(theta) in Eq. (14) and (21). */
    vd G[NMAX][CMAX];
    for (int i = 0; i < n; i++) {
        vd rel[3];
        for (int q = 0; q < 3; q++)
            rel[q] = p_u[q] - F->o[i][q];
        cross(F->R[i][2], rel, G[i]);
        for (int q = 3; q < c; q++)
            G[i][q] = F->R[i][2][q - 3];
    }

    /* The torques' dependence on the geometry, in the undeflected chain: each parameter
       of row i moves frames i + 1.. by a twist; M_f, V_f turn the twist into
       sum_j H_j d tau_j (_compliance.torque_adjoint). ext holds these terms per row
       parameter, turn those of a turn of each joint, camload those of the first
       marker's translation (it moves the load point). Every term is a multiple of some
       lambda*_j: with all of them zero they vanish and are skipped (adj 0). */
    vd ext[NMAX][5][CMAX], turn[NMAX][CMAX], camload[3][CMAX] = {{vsplat(0.0)}};
    Adjoint A;
    if (adj) {
        for (int j = 0; j < n; j++)
            for (int q = 0; q < c; q++)
                A.H[j][q] = lam[j] * G[j][q];
        for (int t = 1; t <= n + 1; t++)
            for (int q = 0; q < c; q++)
                for (int b = 0; b < 3; b++)
                    A.dM[t][q][b] = A.dV[t][q][b] = vsplat(0.0);
        for (int j = 0; j < n; j++) {
            /* Load torque: axis still, (omega x p + vel) . (g x z); axis moved,
               (z x r) . (g x omega). */
            const vd *z = F0.R[j][2];
            vd gz[3], up[3], rr[3], zr[3], down[3];
            cross(gv, z, gz);
            scale3(gz, ls);
            for (int q = 0; q < 3; q++)
                rr[q] = p_load[q] - F0.o[j][q];
            cross(p_load, gz, up);
            add_term(&A, c, n + 1, j, up, gz);
            cross(z, rr, zr);
            cross(zr, gv, down);
            for (int q = 0; q < 3; q++) {
                down[q] = down[q] * ls - up[q];
                gz[q] = -gz[q];
            }
            add_term(&A, c, j, j, down, gz);
        }
        if (h[H_LINK]) { /* the lumped moments (_compliance._link_terms) */
            int sh = (int)h[H_SHOULDER], el = (int)h[H_ELBOW], wf = (int)h[H_WRIST];
            int js = sh - 1, je = el - 1;
            double s_x = slink[0], s_u_sh = slink[1], s_u_el = slink[h[H_LINK] == 1 ? 1 : 2];
            const vd *z_sh = F0.R[sh - 1][2], *z_el = F0.R[el - 1][2], *o_wf = F0.o[wf];
            vd xh[3], xg[3], ug[3], mg[3], w[3], gzs[3], gze[3];
            for (int q = 0; q < 3; q++)
                xh[q] = xs * F0.R[sh][0][q];
            cross(xh, gv, xg);
            cross(u, gv, ug);
            for (int q = 0; q < 3; q++)
                mg[q] = s_x * xg[q] + s_u_sh * ug[q];
            cross(z_sh, mg, w);
            add_term(&A, c, sh - 1, js, w, NULL); /* the shoulder axis turns */
            cross(gv, z_sh, gzs);
            cross(xh, gzs, w);
            scale3(w, vsplat(s_x));
            add_term(&A, c, sh, js, w, NULL); /* x-hat turns with frame sh */
            du_terms(&A, c, js, s_u_sh, gzs, u, z_el, o_wf, norm, el, wf);
            cross(z_el, ug, w);
            scale3(w, vsplat(s_u_el));
            add_term(&A, c, el - 1, je, w, NULL); /* the elbow axis turns */
            cross(gv, z_el, gze);
            du_terms(&A, c, je, s_u_el, gze, u, z_el, o_wf, norm, el, wf);
        }
        const long long *bodies = h + h[H_I_BODIES];
        int n_lump = h[H_LINK] == 0 ? 0 : (h[H_LINK] == 1 ? 2 : 3);
        for (int b = 0; b < (int)h[H_NBODIES]; b++) { /* _compliance._body_terms */
            int kf = (int)bodies[b];
            const double *coef = slink + n_lump + 4 * b;
            double mass = coef[0];
            vd Mk[3], Mo[3];
            for (int q = 0; q < 3; q++) {
                Mk[q] = F0.R[kf][0][q] * coef[1] + F0.R[kf][1][q] * coef[2] +
                        F0.R[kf][2][q] * coef[3];
                Mo[q] = Mk[q] + mass * F0.o[kf][q];
            }
            for (int j = 0; j < kf; j++) {
                const vd *z = F0.R[j][2], *oj = F0.o[j];
                vd gz[3], lever[3], lg[3], w[3], og[3], v[3];
                cross(gv, z, gz);
                for (int q = 0; q < 3; q++)
                    lever[q] = Mo[q] - mass * oj[q];
                cross(lever, gv, lg);
                cross(z, lg, w);
                cross(oj, gz, og);
                for (int q = 0; q < 3; q++) {
                    w[q] -= mass * og[q];
                    v[q] = -mass * gz[q];
                }
                add_term(&A, c, j, j, w, v); /* the axis turns; the lever's ends move */
                cross(Mo, gz, w);
                for (int q = 0; q < 3; q++)
                    v[q] = mass * gz[q];
                add_term(&A, c, kf, j, w, v);
            }
        }
        /* The sweep from the wrist down: M_f = sum_{t >= f} dM[t]. */
        vd Ms[CMAX][3], Vs[CMAX][3];
        for (int q = 0; q < c; q++)
            for (int b = 0; b < 3; b++) {
                Ms[q][b] = A.dM[n + 1][q][b];
                Vs[q][b] = A.dV[n + 1][q][b];
            }
        for (int a = 0; a < 3; a++)
            mat_apply(c, Vs, F0.R[n][a], camload[a]);
        for (int f = n; f >= 1; f--) {
            for (int q = 0; q < c; q++)
                for (int b = 0; b < 3; b++) {
                    Ms[q][b] += A.dM[f][q][b];
                    Vs[q][b] += A.dV[f][q][b];
                }
            int i = f - 1;
            const long long *idx = row_idx + 5 * i;
            const vd *z = F0.R[i][2], *o = F0.o[i], *ax = F0.ax[i], *o1 = F0.o[i + 1];
            vd oz[3];
            cross(o, z, oz); /* joint f turning about z_i through o_i */
            mat_apply(c, Ms, z, turn[i]);
            mat_apply_add(c, Vs, oz, turn[i]);
            if (idx[R_D] >= 0)
                mat_apply(c, Vs, z, ext[i][R_D]);
            if (idx[R_A] >= 0)
                mat_apply(c, Vs, ax, ext[i][R_A]);
            if (idx[R_ALPHA] >= 0) {
                vd oa[3];
                cross(o1, ax, oa);
                mat_apply(c, Ms, ax, ext[i][R_ALPHA]);
                mat_apply_add(c, Vs, oa, ext[i][R_ALPHA]);
            }
            if (idx[R_BETA] >= 0) {
                const vd *y = F0.R[i + 1][1];
                vd oy[3];
                cross(o1, y, oy);
                mat_apply(c, Ms, y, ext[i][R_BETA]);
                mat_apply_add(c, Vs, oy, ext[i][R_BETA]);
            }
        }
    }
    if (load) {
        /* lambda* columns (Eq. 24): d output / d theta_j tau_j; link columns and products
           (Eq. 26). */
        vd col[CMAX];
        for (int j = 0; j < n; j++) {
            for (int q = 0; q < c; q++)
                col[q] = G[j][q] * tau[j];
            PUT(h[H_LAM_START] + j, col);
        }
        vd linkcol[LMAX][CMAX];
        int nlink = (int)h[H_NLINK];
        for (int kc = 0; kc < nlink; kc++)
            for (int q = 0; q < c; q++)
                linkcol[kc][q] = vsplat(0.0);
        for (int p = 0; p < nprod; p++) {
            int j = (int)prod[5 * p], kcol = (int)prod[5 * p + 1];
            for (int q = 0; q < c && adj; q++)
                linkcol[kcol][q] += A.H[j][q] * ltp[p];
            if (p < (int)h[H_K]) {
                for (int q = 0; q < c; q++)
                    col[q] = G[j][q] * ltp[p];
                PUT(h[H_P] + p, col);
            }
        }
        for (int kc = 0; kc < nlink; kc++)
            PUT(h[H_LINK_START] + kc, linkcol[kc]);
    }

    /* Joint rows (Eq. 10; deflected chain) plus the torque terms. */
    for (int i = 0; i < n; i++) {
        const long long *idx = row_idx + 5 * i;
        vd col[CMAX], rel[3];
        if (idx[R_OFF] >= 0) {
            for (int q = 0; q < c; q++)
                col[q] = adj ? G[i][q] + turn[i][q] : G[i][q];
            PUT(idx[R_OFF], col);
        }
        if (idx[R_D] >= 0) {
            for (int q = 0; q < c; q++)
                col[q] = q < 3 ? F->R[i][2][q] : vsplat(0.0);
            if (adj)
                for (int q = 0; q < c; q++)
                    col[q] += ext[i][R_D][q];
            PUT(idx[R_D], col);
        }
        if (idx[R_A] >= 0) {
            for (int q = 0; q < c; q++)
                col[q] = q < 3 ? F->ax[i][q] : vsplat(0.0);
            if (adj)
                for (int q = 0; q < c; q++)
                    col[q] += ext[i][R_A][q];
            PUT(idx[R_A], col);
        }
        for (int q = 0; q < 3; q++)
            rel[q] = p_u[q] - F->o[i + 1][q];
        if (idx[R_ALPHA] >= 0) {
            cross(F->ax[i], rel, col);
            for (int q = 3; q < c; q++)
                col[q] = F->ax[i][q - 3];
            if (adj)
                for (int q = 0; q < c; q++)
                    col[q] += ext[i][R_ALPHA][q];
            PUT(idx[R_ALPHA], col);
        }
        if (idx[R_BETA] >= 0) {
            const vd *y = F->R[i + 1][1];
            cross(y, rel, col);
            for (int q = 3; q < c; q++)
                col[q] = y[q - 3];
            if (adj)
                for (int q = 0; q < c; q++)
                    col[q] += ext[i][R_BETA][q];
            PUT(idx[R_BETA], col);
        }
    }

    /* NTM terms (Eq. 14, 17) turn their joint: through the chain and through the
       torques. */
    for (int kk = 0; kk < nntm; kk++) {
        int j = (int)ntm_j[kk];
        vd dturn[CMAX], col[CMAX];
        for (int q = 0; q < c; q++)
            dturn[q] = adj ? G[j][q] + turn[j][q] : G[j][q];
        for (int b = 0; b < nb; b++) {
            vd B = vload(in->basis + (kk * nb + b) * N + k);
            for (int q = 0; q < c; q++)
                col[q] = dturn[q] * B;
            PUT(h[H_NTM_START] + kk * nb + b, col);
        }
    }

    /* Cam frames (Eq. 9): the lane's marker only. */
    vd rel_cam[3];
    for (int q = 0; q < 3; q++)
        rel_cam[q] = Rn[0][q] * p_cam_fl[0] + Rn[1][q] * p_cam_fl[1] + Rn[2][q] * p_cam_fl[2];
    for (int mm = 0; mm < M; mm++) {
        const long long *idx = cam_idx + 6 * mm;
        vm mine = {0};
        for (int l = 0; l < LANES; l++)
            LANE(mine, l) = midx[l] == mm ? -1 : 0;
        vd col[CMAX];
        for (int a = 0; a < 3; a++) {
            for (int q = 0; q < c; q++) {
                vd v = q < 3 ? vsel(mine, Rn[a][q], vsplat(0.0)) : vsplat(0.0);
                col[q] = (adj && mm == 0) ? v + camload[a][q] : v;
            }
            PUT(idx[a], col);
        }
        if (!h[H_CAM_ROT])
            continue;
        const double *axes = cam_t + 21 * mm + 12;
        for (int a = 0; a < 3; a++) {
            vd axb[3];
            for (int q = 0; q < 3; q++) /* the Euler axis in the user frame */
                axb[q] = Rn[0][q] * axes[3 * a] + Rn[1][q] * axes[3 * a + 1] +
                         Rn[2][q] * axes[3 * a + 2];
            cross(axb, rel_cam, col);
            for (int q = 3; q < c; q++)
                col[q] = axb[q - 3];
            for (int q = 0; q < c; q++)
                col[q] = vsel(mine, col[q], vsplat(0.0));
            PUT(idx[3 + a], col);
        }
    }

    /* User frames (Eq. 8): the lane's set only. */
    vd rel_b[3];
    for (int q = 0; q < 3; q++)
        rel_b[q] = p_u[q] - tb[q];
    for (int ss = 0; ss < S; ss++) {
        const long long *idx = base_idx + 6 * ss;
        const double *axes = base_t + 24 * ss + 15;
        vm mine = {0};
        for (int l = 0; l < LANES; l++)
            LANE(mine, l) = sidx[l] == ss ? -1 : 0;
        vd col[CMAX], one = vsel(mine, vsplat(1.0), vsplat(0.0));
        for (int a = 0; a < 3; a++) {
            for (int q = 0; q < c; q++)
                col[q] = q == a ? one : vsplat(0.0);
            PUT(idx[a], col);
        }
        for (int a = 0; a < 3; a++) {
            vd axis[3];
            for (int q = 0; q < 3; q++)
                axis[q] = vsplat(axes[3 * a + q]);
            cross(axis, rel_b, col);
            for (int q = 3; q < c; q++)
                col[q] = axis[q - 3];
            for (int q = 0; q < c; q++)
                col[q] = vsel(mine, col[q], vsplat(0.0));
            PUT(idx[3 + a], col);
        }
    }
#undef PUT
}

/* Poses k0 <= k < k1, k1 - k0 a multiple of LANES. */
KC_TARGET static void run_full(const Args *in, Py_ssize_t k0, Py_ssize_t k1)
{
    int c = (int)in->h[H_C];
    for (Py_ssize_t k = k0; k + LANES <= k1; k += LANES) {
        if (c == 3)
            block(in, k, 3);
        else
            block(in, k, 6);
    }
}

/* Poses k0 <= k < k1 in blocks of LANES; a last partial block runs on copies of its
   poses padded with the last one, and only its own lanes are copied back. */
KC_TARGET static int run_blocks(const Args *in, Py_ssize_t k0, Py_ssize_t k1)
{
    const long long *h = in->h;
    Py_ssize_t full = k0 + (k1 - k0) / LANES * LANES, N = in->N, rest = k1 - full;
    run_full(in, k0, full);
    if (rest == 0)
        return 0;
    long long n = h[H_N], c = h[H_C], nbas = h[H_NNTM] * h[H_NB];
    long long cols = h[H_JACOBIAN] ? h[H_P] + h[H_K] : 0;
    size_t count = (size_t)LANES * (4 * n + nbas + 3 + 1 + 3 + 9 + cols * c);
    double *buf = malloc(count * sizeof(double));
    long long idx[2 * LANES];
    if (!buf)
        return -1;
    Args t = *in;
    double *thc = buf, *cq = thc + n * LANES, *sq = cq + n * LANES, *basis = sq + n * LANES;
    double *p_cam = basis + nbas * LANES, *ls = p_cam + 3 * LANES, *p_user = ls + LANES;
    double *R_uc = p_user + 3 * LANES, *theta = R_uc + 9 * LANES, *J = theta + n * LANES;
    for (int l = 0; l < LANES; l++) {
        Py_ssize_t src = full + (l < rest ? l : rest - 1);
        for (long long i = 0; i < n; i++) {
            thc[i * LANES + l] = in->thc[i * N + src];
            cq[i * LANES + l] = in->cq[i * N + src];
            sq[i * LANES + l] = in->sq[i * N + src];
        }
        for (long long b = 0; b < nbas; b++)
            basis[b * LANES + l] = in->basis[b * N + src];
        for (int q = 0; q < 3; q++)
            p_cam[3 * l + q] = in->p_cam[3 * src + q];
        ls[l] = in->load_scale[src];
        idx[l] = in->set_index[src];
        idx[LANES + l] = in->marker_index[src];
    }
    t.N = LANES;
    t.thc = thc;
    t.cq = cq;
    t.sq = sq;
    t.basis = basis;
    t.p_cam = p_cam;
    t.load_scale = ls;
    t.set_index = idx;
    t.marker_index = idx + LANES;
    t.p_user = p_user;
    t.R_uc = in->R_uc ? R_uc : NULL;
    t.theta = theta;
    t.J = J;
    run_full(&t, 0, LANES);
    for (Py_ssize_t l = 0; l < rest; l++) {
        Py_ssize_t dst = full + l;
        for (int q = 0; q < 3; q++)
            in->p_user[3 * dst + q] = p_user[3 * l + q];
        if (in->R_uc)
            for (int q = 0; q < 9; q++)
                in->R_uc[9 * dst + q] = R_uc[9 * l + q];
        for (long long i = 0; i < n; i++)
            in->theta[i * N + dst] = theta[i * LANES + l];
        for (long long e = 0; e < cols * c; e++)
            in->J[e * N + dst] = J[e * LANES + l];
    }
    free(buf);
    return 0;
}

#undef vd
#undef vm
#undef vload
#undef vstore
#undef vsplat
#undef vsel
#undef vsqrt
#undef gather
#undef cross
#undef dot
#undef scale3
#undef shift
#undef Chain
#undef chain
#undef Adjoint
#undef add_term
#undef mat_apply
#undef mat_apply_add
#undef du_terms
#undef block
#undef run_full
#undef run_blocks
#undef LANE
#undef INLINE
#undef LANES
#undef KC_TARGET
#undef KC_SUFFIX
#else /* the module */

/* ------------------------------------------------------------------ checks, module */
static int in_range(long long v, long long lo, long long hi) { return v >= lo && v < hi; }

/* The tables lie inside their buffers and every index they hold is in range (the
   kernel trusts them afterwards). */
static int tables_valid(const long long *h, Py_ssize_t n_ints, Py_ssize_t n_reals)
{
    long long n = h[H_N], S = h[H_SETS], M = h[H_MARKERS], P = h[H_P], c = h[H_C];
    long long nprod = h[H_NPROD], nlink = h[H_NLINK], nntm = h[H_NNTM], nb = h[H_NB];
    if (!in_range(n, 1, NMAX + 1) || S < 1 || M < 1 || (c != 3 && c != 6) ||
        !in_range(nprod, 0, PMAX + 1) || !in_range(nlink, 0, LMAX + 1) ||
        !in_range(h[H_K], 0, nprod + 1) || nntm < 0 || nb < 0 || h[H_NBODIES] < 0)
        return -1;
    long long ints[][2] = {
        {h[H_I_ROWIDX], 5 * n}, {h[H_I_CAMIDX], 6 * M},        {h[H_I_BASEIDX], 6 * S},
        {h[H_I_NTMJ], nntm},    {h[H_I_BODIES], h[H_NBODIES]}, {h[H_I_PROD], 5 * nprod},
    };
    long long reals[][2] = {
        {h[H_R_ROWS], 8 * n}, {h[H_R_BASE], 24 * S}, {h[H_R_CAM], 21 * M},
        {h[H_R_LAM], n},      {h[H_R_LINK], nlink},  {h[H_R_NTM], nntm * nb},
        {h[H_R_XSIGN], 1},
    };
    for (size_t i = 0; i < sizeof ints / sizeof ints[0]; i++)
        if (ints[i][0] < H_COUNT || ints[i][0] + ints[i][1] > n_ints)
            return -1;
    for (size_t i = 0; i < sizeof reals / sizeof reals[0]; i++)
        if (reals[i][0] < 0 || reals[i][0] + reals[i][1] > n_reals)
            return -1;
    for (long long i = 0; i < 5 * n; i++)
        if (!in_range(h[h[H_I_ROWIDX] + i], -1, P))
            return -1;
    for (long long i = 0; i < 6 * M; i++) {
        long long v = h[h[H_I_CAMIDX] + i];
        if (!in_range(v, (i % 6 < 3 || h[H_CAM_ROT]) ? 0 : -1, P))
            return -1;
    }
    for (long long i = 0; i < 6 * S; i++)
        if (!in_range(h[h[H_I_BASEIDX] + i], 0, P))
            return -1;
    for (long long i = 0; i < nntm; i++)
        if (!in_range(h[h[H_I_NTMJ] + i], 0, n))
            return -1;
    if (nntm && (h[H_NTM_START] < 0 || h[H_NTM_START] + nntm * nb > P))
        return -1;
    if (!h[H_LOAD])
        return (nprod || nlink || h[H_LINK] || h[H_NBODIES]) ? -1 : 0;
    if (h[H_LAM_START] < 0 || h[H_LAM_START] + n > P || h[H_LINK_START] < 0 ||
        h[H_LINK_START] + nlink > P || !in_range(h[H_LINK], 0, 3))
        return -1;
    long long n_lump = h[H_LINK] == 0 ? 0 : (h[H_LINK] == 1 ? 2 : 3);
    if (n_lump && (!in_range(h[H_SHOULDER], 1, n + 1) || !in_range(h[H_ELBOW], 1, n + 1) ||
                   !in_range(h[H_WRIST], 0, n + 1)))
        return -1;
    if (n_lump + 4 * h[H_NBODIES] != nlink)
        return -1;
    for (long long i = 0; i < h[H_NBODIES]; i++)
        if (!in_range(h[h[H_I_BODIES] + i], 1, n + 1))
            return -1;
    for (long long p = 0; p < nprod; p++) {
        const long long *d = h + h[H_I_PROD] + 5 * p;
        if (!in_range(d[0], 0, n) || !in_range(d[1], 0, nlink) || !in_range(d[2], 0, 4) ||
            !in_range(d[3], 0, n + 1) || !in_range(d[4], 0, 3) || (d[2] < 2 && !n_lump))
            return -1;
    }
    return 0;
}

static int need(const Py_buffer *b, Py_ssize_t count, const char *name)
{
    if (b->len != count * (Py_ssize_t)sizeof(double)) {
        PyErr_Format(PyExc_ValueError, "_ckernel.evaluate: %s has %zd bytes; expected %zd",
                     name, b->len, count * (Py_ssize_t)sizeof(double));
        return -1;
    }
    return 0;
}

PyDoc_STRVAR(evaluate_doc,
"evaluate(ints, reals, theta_c, cos_c, sin_c, basis, set_index, marker_index, p_cam,\n"
"         load_scale, p_user, R_user_cam, theta, J, k0, k1)\n"
"\n"
"Evaluate poses k0 <= k < k1 in place. Inputs: the int64 header and tables, the float64\n"
"tables, the coupled angles with their cos and sin (n, N), the NTM bases (n_ntm, nb, N),\n"
"set and marker indices (N,) int64, p_cam (N, 3), load_scale (N,). Outputs: p_user\n"
"(N, 3), R_user_cam (N, 3, 3) or empty, theta (n, N), J (P + K, c, N) or empty. All\n"
"C-contiguous. Raises IndexError for a set or marker index out of range, ValueError for\n"
"tables or arrays that do not match.");

static PyObject *evaluate(PyObject *Py_UNUSED(self), PyObject *args)
{
    Py_buffer b[14];
    Py_ssize_t k0, k1;
    memset(b, 0, sizeof b);
    if (!PyArg_ParseTuple(args, "y*y*y*y*y*y*y*y*y*y*w*w*w*w*nn", &b[0], &b[1], &b[2],
                          &b[3], &b[4], &b[5], &b[6], &b[7], &b[8], &b[9], &b[10], &b[11],
                          &b[12], &b[13], &k0, &k1))
        return NULL;
    PyObject *result = NULL;
    Args a;
    const long long *h = (const long long *)b[0].buf;
    Py_ssize_t N = b[9].len / (Py_ssize_t)sizeof(double);
    if (b[0].len < H_COUNT * (Py_ssize_t)sizeof(long long) ||
        tables_valid(h, b[0].len / (Py_ssize_t)sizeof(long long),
                     b[1].len / (Py_ssize_t)sizeof(double))) {
        PyErr_SetString(PyExc_ValueError, "_ckernel.evaluate: inconsistent tables");
        goto done;
    }
    long long n = h[H_N], c = h[H_C];
    if (k0 < 0 || k1 > N || k0 > k1) {
        PyErr_SetString(PyExc_ValueError, "_ckernel.evaluate: bad pose range");
        goto done;
    }
    if (need(&b[2], n * N, "theta_c") || need(&b[3], n * N, "cos_c") ||
        need(&b[4], n * N, "sin_c") || need(&b[5], h[H_NNTM] * h[H_NB] * N, "basis") ||
        need(&b[6], N, "set_index") || need(&b[7], N, "marker_index") ||
        need(&b[8], 3 * N, "p_cam") || need(&b[10], 3 * N, "p_user") ||
        need(&b[12], n * N, "theta"))
        goto done;
    if (b[11].len != 0 && need(&b[11], 9 * N, "R_user_cam"))
        goto done;
    if (h[H_JACOBIAN] && need(&b[13], (h[H_P] + h[H_K]) * c * N, "J"))
        goto done;
    a.h = h;
    a.r = (const double *)b[1].buf;
    a.N = N;
    a.thc = b[2].buf;
    a.cq = b[3].buf;
    a.sq = b[4].buf;
    a.basis = b[5].buf;
    a.set_index = b[6].buf;
    a.marker_index = b[7].buf;
    a.p_cam = b[8].buf;
    a.load_scale = b[9].buf;
    a.p_user = b[10].buf;
    a.R_uc = b[11].len ? b[11].buf : NULL;
    a.theta = b[12].buf;
    a.J = b[13].buf;
    for (Py_ssize_t k = k0; k < k1; k++) { /* checked first: the blocks trust them */
        long long s = a.set_index[k], m = a.marker_index[k];
        if (s < 0 || s >= h[H_SETS] || m < 0 || m >= h[H_MARKERS]) {
            PyErr_Format(PyExc_IndexError,
                         "pose %zd: set index %lld or marker index %lld out of range "
                         "(the model has %lld sets and %lld markers)",
                         k, s, m, h[H_SETS], h[H_MARKERS]);
            goto done;
        }
    }
    int status;
    Py_BEGIN_ALLOW_THREADS
    status = widths[width].run(&a, k0, k1);
    Py_END_ALLOW_THREADS
    if (status) {
        PyErr_NoMemory();
        goto done;
    }
    result = Py_NewRef(Py_None);
done:
    for (int i = 0; i < 14; i++)
        if (b[i].obj)
            PyBuffer_Release(&b[i]);
    return result;
}

/* ------------------------------------------------------------------ normal equations */
/* The products of the normal equations of a held Jacobian (kinecal.identification.
   _normal): the upper triangle of [X; r] [X; r]^T, X the rows lo .. hi - 1 of a
   parameter-major Jacobian J (P', c, N) (a row per parameter, its columns in (component,
   pose) order), r (N, c) the residuals, both weighted by w (N,) per pose when given. The
   columns are copied by blocks of GRAM_ROWS into a scratch of k + 1 contiguous rows (hot
   in cache), whose products are summed four columns a vector in tiles of 2 x 4 outputs,
   multiplies and adds apart (no fused multiply-adds, as the kernel). For the tall, narrow
   products of a calibration this beats BLAS dsyrk on the same Jacobian (2000 poses x 50
   parameters, one AVX core: 0.49-0.51 against 0.58-0.60 ms): dsyrk reads the 48
   kB-strided rows of the Jacobian in place. AVX only (GCC and Clang on x86), chosen at run time; GRAM
   says whether it serves, and the caller uses BLAS otherwise. The sums are in a fixed
   order: the same numbers on every run and thread count. */
#if (defined(__GNUC__) || defined(__clang__)) && (defined(__x86_64__) || defined(__i386__))
#define HAVE_GRAM 1
#include <immintrin.h>
#define GRAM_ROWS 192 /* columns per block: (k + 1) x 192 doubles, 77 kB at k = 50 */

/* A (ld, ld), row-major, upper triangle: A[idx[a], idx[b]] += (S S^T)[a, b], S (k,
   GRAM_ROWS), idx increasing. */
__attribute__((target("avx"))) static void gram_tiles(const double *S, Py_ssize_t k,
                                                      const Py_ssize_t *idx, Py_ssize_t ld,
                                                      double *A)
{
    for (Py_ssize_t i = 0; i < k; i += 2) {
        const double *a0 = S + i * GRAM_ROWS, *a1 = S + (i + 1 < k ? i + 1 : i) * GRAM_ROWS;
        for (Py_ssize_t j = i; j < k; j += 4) {
            const double *b[4];
            for (int v = 0; v < 4; v++)
                b[v] = S + (j + v < k ? j + v : k - 1) * GRAM_ROWS;
            __m256d s[2][4];
            for (int v = 0; v < 4; v++)
                s[0][v] = s[1][v] = _mm256_setzero_pd();
            for (int q = 0; q < GRAM_ROWS; q += 4) {
                __m256d x0 = _mm256_loadu_pd(a0 + q), x1 = _mm256_loadu_pd(a1 + q);
                for (int v = 0; v < 4; v++) {
                    __m256d y = _mm256_loadu_pd(b[v] + q);
                    s[0][v] = _mm256_add_pd(s[0][v], _mm256_mul_pd(x0, y));
                    s[1][v] = _mm256_add_pd(s[1][v], _mm256_mul_pd(x1, y));
                }
            }
            double t[4];
            for (int u = 0; u < 2 && i + u < k; u++)
                for (int v = 0; v < 4 && j + v < k; v++) {
                    if (j + v < i + u)
                        continue; /* below the diagonal */
                    _mm256_storeu_pd(t, s[u][v]);
                    A[idx[i + u] * ld + idx[j + v]] += (t[0] + t[1]) + (t[2] + t[3]);
                }
        }
    }
}

/* out (k + 1, k + 1) += the products of the rows lo .. lo + k - 1 of J and r. A block's
   rows of zeros are left out of its products (they add nothing): a frame's translation in
   its other components, the columns of the user frames and markers of other poses. idx
   (k + 1) is scratch. */
static void gram_run(const double *J, Py_ssize_t c, Py_ssize_t N, Py_ssize_t lo,
                     Py_ssize_t k, const double *r, const double *w, double *S,
                     Py_ssize_t *idx, double *out)
{
    for (Py_ssize_t q = 0; q < c; q++)
        for (Py_ssize_t s0 = 0; s0 < N; s0 += GRAM_ROWS) {
            Py_ssize_t m = N - s0 < GRAM_ROWS ? N - s0 : GRAM_ROWS, rows = 0;
            for (Py_ssize_t i = 0; i <= k; i++) {
                double *dst = S + rows * GRAM_ROWS;
                if (i == k) /* the residuals, last */
                    for (Py_ssize_t t = 0; t < m; t++)
                        dst[t] = w ? r[(s0 + t) * c + q] * w[s0 + t] : r[(s0 + t) * c + q];
                else if (w)
                    for (Py_ssize_t t = 0; t < m; t++)
                        dst[t] = J[((lo + i) * c + q) * N + s0 + t] * w[s0 + t];
                else
                    memcpy(dst, J + ((lo + i) * c + q) * N + s0, (size_t)m * sizeof(double));
                if (m < GRAM_ROWS)
                    memset(dst + m, 0, (size_t)(GRAM_ROWS - m) * sizeof(double));
                for (Py_ssize_t t = 0; t < m; t++)
                    if (dst[t] != 0.0) { /* NaN too */
                        idx[rows++] = i;
                        break;
                    }
            }
            if (rows)
                gram_tiles(S, rows, idx, k + 1, out);
        }
}
#endif

PyDoc_STRVAR(gram_doc,
"gram(J, r, w, out, c, lo, hi)\n"
"\n"
"Add the upper triangle of [X; r] [X; r]^T to out (k + 1, k + 1), k = hi - lo: X the\n"
"rows lo <= p < hi of the parameter-major Jacobian J (P', c, N), r (N, c) the residuals,\n"
"both weighted by w (N,) per pose (empty: none). All float64, C-contiguous. Only where\n"
"GRAM is 1 (RuntimeError otherwise).");

static int gram_ok = 0; /* built with the AVX code and this CPU runs it */

static PyObject *gram(PyObject *Py_UNUSED(self), PyObject *args)
{
    Py_buffer b[4];
    Py_ssize_t c, lo, hi;
    memset(b, 0, sizeof b);
    if (!PyArg_ParseTuple(args, "y*y*y*w*nnn", &b[0], &b[1], &b[2], &b[3], &c, &lo, &hi))
        return NULL;
    PyObject *result = NULL;
    Py_ssize_t d = (Py_ssize_t)sizeof(double), N = c > 0 ? b[1].len / d / c : 0;
    Py_ssize_t k = hi - lo, P = c > 0 && N > 0 ? b[0].len / d / c / N : 0;
    if (!gram_ok) {
        PyErr_SetString(PyExc_RuntimeError, "_ckernel.gram: not available here");
        goto done;
    }
    if (c < 1 || N < 1 || b[1].len != N * c * d || b[0].len != P * c * N * d || lo < 0 ||
        hi > P || k < 1 || (b[2].len != 0 && b[2].len != N * d) ||
        b[3].len != (k + 1) * (k + 1) * d) {
        PyErr_SetString(PyExc_ValueError, "_ckernel.gram: arrays that do not match");
        goto done;
    }
#ifdef HAVE_GRAM
    /* The scratch on a cache line: a vector load across two lines costs twice (0.67
       against 0.46 ms on the 16-byte boundaries of malloc). */
    size_t row = GRAM_ROWS * sizeof(double) + sizeof(Py_ssize_t); /* and its index */
    void *mem = malloc((size_t)(k + 1) * row + 64);
    if (!mem) {
        PyErr_NoMemory();
        goto done;
    }
    double *S = (double *)(((uintptr_t)mem + 63) & ~(uintptr_t)63);
    Py_ssize_t *idx = (Py_ssize_t *)(S + (k + 1) * GRAM_ROWS);
    Py_BEGIN_ALLOW_THREADS
    gram_run(b[0].buf, c, N, lo, k, b[1].buf, b[2].len ? b[2].buf : NULL, S, idx, b[3].buf);
    Py_END_ALLOW_THREADS
    free(mem);
#endif
    result = Py_NewRef(Py_None);
done:
    for (int i = 0; i < 4; i++)
        if (b[i].obj)
            PyBuffer_Release(&b[i]);
    return result;
}

PyDoc_STRVAR(lanes_doc,
"lanes(n=0)\n"
"\n"
"The poses per vector of evaluate() (2 the baseline; 4 with AVX2, 8 with AVX-512F where\n"
"built and the CPU runs them: the widest is chosen when the module loads). With n > 0,\n"
"use that width from now on (ValueError where this build or CPU has not it). Every\n"
"width gives the same numbers.");

static PyObject *lanes(PyObject *Py_UNUSED(self), PyObject *args)
{
    int n = 0;
    if (!PyArg_ParseTuple(args, "|i", &n))
        return NULL;
    if (n > 0) {
        int found = -1;
        for (int i = 0; i < N_WIDTHS; i++)
            if (widths[i].lanes == n && width_ok[i])
                found = i;
        if (found < 0) {
            PyErr_Format(PyExc_ValueError, "_ckernel.lanes: %d lanes not available here", n);
            return NULL;
        }
        width = found;
    }
    return PyLong_FromLong(widths[width].lanes);
}

static PyMethodDef methods[] = {
    {"evaluate", evaluate, METH_VARARGS, evaluate_doc},
    {"lanes", lanes, METH_VARARGS, lanes_doc},
    {"gram", gram, METH_VARARGS, gram_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT,
    "_ckernel",
    "The calibration model's forward kinematics and parameter Jacobian in compiled code "
    "(see kinecal.models._kernel).",
    -1,
    methods,
    NULL,
    NULL,
    NULL,
    NULL,
};

PyMODINIT_FUNC PyInit__ckernel(void)
{
    PyObject *mod = PyModule_Create(&module);
    if (!mod)
        return NULL;
    PyObject *fields = PyTuple_New(H_COUNT);
    if (!fields) {
        Py_DECREF(mod);
        return NULL;
    }
    for (int i = 0; i < H_COUNT; i++) {
        PyObject *name = PyUnicode_FromString(FIELDS[i]);
        if (!name) {
            Py_DECREF(fields);
            Py_DECREF(mod);
            return NULL;
        }
        if (PyTuple_SetItem(fields, i, name) < 0) { /* steals name, even on failure */
            Py_DECREF(fields);
            Py_DECREF(mod);
            return NULL;
        }
    }
    if (PyModule_AddObject(mod, "FIELDS", fields) < 0) {
        Py_DECREF(fields);
        Py_DECREF(mod);
        return NULL;
    }
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__)
    __builtin_cpu_init();
#endif
    PyObject *built = PyTuple_New(N_WIDTHS); /* WIDTHS: the lanes of this build's widths */
    for (int i = 0; built && i < N_WIDTHS; i++) {
        PyObject *v = PyLong_FromLong(widths[i].lanes);
        if (!v || PyTuple_SetItem(built, i, v) < 0) {
            Py_CLEAR(built);
        }
    }
    if (!built || PyModule_AddObject(mod, "WIDTHS", built) < 0) {
        Py_XDECREF(built);
        Py_DECREF(mod);
        return NULL;
    }
    for (int i = 0; i < N_WIDTHS; i++) { /* the widest this CPU runs */
        width_ok[i] = widths[i].cpu == NULL;
#ifdef HAVE_WIDE
        if (widths[i].lanes == 4)
            width_ok[i] = __builtin_cpu_supports("avx2") != 0;
        else if (widths[i].lanes == 8)
            width_ok[i] = __builtin_cpu_supports("avx512f") != 0;
#endif
        if (width_ok[i])
            width = i;
    }
    if (PyModule_AddIntConstant(mod, "MAX_JOINTS", NMAX) < 0 ||
        PyModule_AddIntConstant(mod, "MAX_PRODUCTS", PMAX) < 0 ||
        PyModule_AddIntConstant(mod, "MAX_LINK", LMAX) < 0 ||
        PyModule_AddIntConstant(mod, "LANES", widths[width].lanes) < 0) {
        Py_DECREF(mod);
        return NULL;
    }
#ifdef HAVE_GRAM
    __builtin_cpu_init();
    gram_ok = __builtin_cpu_supports("avx") != 0;
#endif
    if (PyModule_AddIntConstant(mod, "GRAM", gram_ok) < 0) {
        Py_DECREF(mod);
        return NULL;
    }
    return mod;
}

#endif /* KC_SUFFIX */
