/* The loop of posturegen.solver.sqp.core in C: the same iterations, in the same order, on
   the same functions (CasADi's function buffers, evaluated in place), with the QPs and the
   convexification that is not a lift by δ asked of Python (:mod:`.native`). Each function
   below is the C of the Python function it names; core.py is the reference and documents
   the method. Compiled by posturegen.solver.sqp.native. */
#include <math.h>
#include <string.h>
#include <time.h>

typedef void (*eval_t)(void *);
typedef void (*potrf_t)(char *, int *, double *, int *, int *);
typedef long (*ask_t)(long);

/* run statuses (native.STATUSES) */
enum { UNFINISHED, SUCCEEDED, ACCEPTABLE, INFEASIBLE, CPU_TIME, STEP_ERROR, TOO_SMALL, ASK_FAILED };
/* what Python is asked: the step's QP (relaxed or elastic as it needs), the second-order
   correction's QP, the convexified model */
enum { ASK_STEP, ASK_SOC, ASK_MODEL };

typedef struct {
    long n, m;
    /* the oracle: nlp_grad_f (f, ∇f), nlp_jac_g (g, J), nlp_hess_l (∇²L, upper) */
    eval_t eval;
    void *fb_grad, *fb_jac, *fb_hess;
    double *in_x, *in_sigma, *in_lam;
    double *out_f, *out_grad, *out_g, *out_jac, *out_hess;
    long nnz_grad, nnz_g, nnz_jac, nnz_hess, n_off;
    long *at_grad, *at_g, *at_jac, *at_upper, *at_mirrored, *off;
    /* the bounds and the variables' scales */
    double *lbx, *ubx, *lbg, *ubg, *scale;
    unsigned char *equal;
    /* options and core's constants */
    long max_iter, stall_iterations, hessian_every, flat_iterations;
    double max_time_s, tol_primal, tol_dual, radius0, radius_min, penalty0;
    double eta, shrink, radius_max, penalty_max, delta, curvature_max, linear_tol, flat_change;
    double penalty_over;
    double *augment;
    long n_augment;
    ask_t ask;
    potrf_t potrf;
    /* two iterates: x (n), ∇f (n), g (m), J (m, n), violations (m), f, ‖viol‖₁, ‖viol‖∞ */
    double *X, *GRAD, *G, *JAC, *VIOL, *F, *L1, *WORST;
    double *lam_g, *lam_x;
    /* the model: ∇²L (n, n), B̃, c̃, Ã, its correction C (k_C, n), the rows and bounds held */
    double *H, *B, *c, *A, *Cm;
    unsigned char *rows, *held_x;
    long k_C, modified, model_version;
    /* the QP's bounds in the region and its working set (the last solved step's duals) */
    double *lb, *ub, *lbA, *ubA, *duals;
    long has_duals;
    double *soc_lbA, *soc_ubA, *soc_duals;
    /* Python's answer (scaled) and the step (unscaled, corrected) */
    double *qd, *qlb, *qlr;
    long q_solved, q_iters, q_elastic;
    double penalty;
    double *d, *lam_b, *lam_r;
    /* the run */
    long iterations, qp_iterations, modified_hessians, status, cur, history_len;
    double wall_s;
    unsigned char *rows_bound;
    double *history;
    /* scratch: (n) x 4, (m + n), (n, n) x 3, (flat_iterations) */
    double *w1, *w2, *w3, *w4, *wm, *wnn, *wnn2, *gram, *costs;
} Sqp;

/* sizeof(Sqp): native.py's record must have this size (else it is not this source's) */
long sqp_size(void) { return (long)sizeof(Sqp); }

typedef struct {
    double *x, *grad, *g, *J, *viol, *f, *l1, *worst;
} It;

static double now(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

/* numpy's maximum and minimum: NaN wins */
static double nmax(double a, double b) { return (a != a || a > b) ? a : b; }
static double nmin(double a, double b) { return (a != a || a < b) ? a : b; }

/* max_abs: ‖v‖∞, 0 for an empty v, NaN when v holds one */
static double max_abs(const double *v, long k) {
    double out = 0.0;
    for (long i = 0; i < k; ++i) out = nmax(out, fabs(v[i]));
    return out;
}

static It slot(const Sqp *s, long k) {
    long n = s->n, m = s->m;
    It it = {s->X + k * n, s->GRAD + k * n, s->G + k * m, s->JAC + k * m * n,
             s->VIOL + k * m, s->F + k, s->L1 + k, s->WORST + k};
    return it;
}

/* Bounds.violation of g into v (m) */
static void violation(const Sqp *s, const double *g, double *v) {
    for (long i = 0; i < s->m; ++i) v[i] = nmax(nmax(s->lbg[i] - g[i], g[i] - s->ubg[i]), 0.0);
}

/* _at: the iterate at it.x (written there, inside the bounds): f, ∇f, g, J, violations */
static void evaluate(Sqp *s, It it) {
    long n = s->n;
    memcpy(s->in_x, it.x, n * sizeof(double));
    s->eval(s->fb_grad);
    s->eval(s->fb_jac);
    *it.f = s->out_f[0];
    for (long k = 0; k < s->nnz_grad; ++k) it.grad[s->at_grad[k]] = s->out_grad[k];
    for (long k = 0; k < s->nnz_g; ++k) it.g[s->at_g[k]] = s->out_g[k];
    for (long k = 0; k < s->nnz_jac; ++k) it.J[s->at_jac[k]] = s->out_jac[k];
    violation(s, it.g, it.viol);
    double l1 = 0.0;
    for (long i = 0; i < s->m; ++i) l1 += it.viol[i];
    *it.l1 = l1;
    *it.worst = max_abs(it.viol, s->m);
}

/* x = clip(a, lbx, ubx) */
static void clipped(const Sqp *s, const double *a, double *x) {
    for (long j = 0; j < s->n; ++j) x[j] = nmin(nmax(a[j], s->lbx[j]), s->ubx[j]);
}

/* out (n) = Jᵀ lam */
static void jt_times(const Sqp *s, const double *J, const double *lam, double *out) {
    long n = s->n;
    memset(out, 0, n * sizeof(double));
    for (long i = 0; i < s->m; ++i) {
        double l = lam[i];
        if (l == 0.0) continue;
        const double *row = J + i * n;
        for (long j = 0; j < n; ++j) out[j] += row[j] * l;
    }
}

/* _converged */
static int converged(Sqp *s, It it, const double *lam_g, const double *lam_x) {
    long n = s->n, m = s->m;
    if (*it.worst > s->tol_primal) return 0;
    double *r = s->w1;
    jt_times(s, it.J, lam_g, r);
    for (long j = 0; j < n; ++j) r[j] = (it.grad[j] + r[j]) + lam_x[j];
    double scale = nmax(1.0, max_abs(it.grad, n));
    if (max_abs(r, n) > s->tol_dual * scale) return 0;
    double worst = 0.0;
    for (long i = 0; i < m; ++i) {
        double gap = lam_g[i] > 0 ? s->ubg[i] - it.g[i] : it.g[i] - s->lbg[i];
        if (!isfinite(gap)) gap = 1e3;
        worst = nmax(worst, fabs(lam_g[i] * gap));
    }
    return worst <= s->tol_dual * scale;
}

/* _stalled */
static long stalled(const Sqp *s, It it) {
    return *it.worst > s->tol_primal ? INFEASIBLE : TOO_SMALL;
}

/* Oracle.hessian at x with σ = 1 and lam (m) into H (n, n), symmetric */
static void hessian(Sqp *s, const double *x, const double *lam) {
    long n = s->n;
    memcpy(s->in_x, x, n * sizeof(double));
    s->in_sigma[0] = 1.0;
    memcpy(s->in_lam, lam, s->m * sizeof(double));
    s->eval(s->fb_hess);
    memset(s->H, 0, n * n * sizeof(double));
    for (long k = 0; k < s->nnz_hess; ++k) s->H[s->at_upper[k]] = s->out_hess[k];
    for (long k = 0; k < s->n_off; ++k) s->H[s->at_mirrored[k]] = s->out_hess[s->off[k]];
}

/* hessian._factorizes: M + shift I has a Cholesky factorization (LAPACK's, as core's) */
static int factorizes(Sqp *s, const double *M, double shift) {
    long n = s->n;
    double *W = s->wnn;
    memcpy(W, M, n * n * sizeof(double));  /* symmetric: its row-major copy is column-major */
    for (long j = 0; j < n; ++j) W[j * n + j] += shift;
    char uplo = 'L';
    int nn = (int)n, lda = (int)n, info = 0;
    s->potrf(&uplo, &nn, W, &lda, &info);
    return info == 0;
}

/* hessian._positive: B - δ/2 I positive definite, |B| within curvature_max */
static int positive(Sqp *s, const double *M) {
    if (max_abs(M, s->n * s->n) > s->curvature_max) return 0;
    return factorizes(s, M, -0.5 * s->delta);
}

/* out = lifted + weight Ĝ (n, n) */
static void weighted(const Sqp *s, const double *lifted, double weight, double *out) {
    for (long k = 0; k < s->n * s->n; ++k) out[k] = lifted[k] + weight * s->gram[k];
}

/* hessian.convexified's second way, from B̃ = S H S + δ I (``lifted``) and max |S H S|: B̃ + τ
   ÂᵀÂ for the first τ of augment (× max(1, max |S H S|)) that makes it positive definite, Â the
   held gradients (the rows held of Ã, then the unit vectors of the bounds held) normalized;
   Cm their C (weight / ‖held‖ × Â). Returns 1 when one does, 0 when Python is to go on. */
static int augmented(Sqp *s, double hs_max) {
    long n = s->n, k = 0;
    double *norms = s->wm, *G = s->gram, *cand = s->wnn2;
    memset(G, 0, n * n * sizeof(double));
    for (long i = 0; i < s->m + n; ++i) {  /* the held gradients, in core's order */
        double norm;
        if (i < s->m) {
            if (!s->rows[i]) continue;
            const double *a = s->A + i * n;
            double sq = 0.0;
            for (long j = 0; j < n; ++j) sq += a[j] * a[j];
            norm = sqrt(sq);
            if (norm > 0)
                for (long p = 0; p < n; ++p) {
                    double up = a[p] / norm;
                    if (up == 0.0) continue;
                    for (long q = 0; q < n; ++q) G[p * n + q] += up * (a[q] / norm);
                }
        } else {
            long j = i - s->m;
            if (!s->held_x[j]) continue;
            norm = 1.0;
            G[j * n + j] += 1.0;
        }
        norms[k++] = norm;
    }
    long any = 0;
    for (long i = 0; i < k; ++i) any |= norms[i] > 0;
    if (!any) return 0;
    double base = fmax(1.0, hs_max);
    weighted(s, s->B, s->augment[s->n_augment - 1] * base, cand);
    if (!(max_abs(cand, n * n) > s->curvature_max || factorizes(s, cand, -0.5 * s->delta)))
        return 0;
    for (long t = 0; t < s->n_augment; ++t) {
        double weight = s->augment[t] * base;
        weighted(s, s->B, weight, cand);
        if (!positive(s, cand)) continue;
        memcpy(s->B, cand, n * n * sizeof(double));
        long h = 0;  /* C: the held gradients × weight / ‖held‖², in their order */
        for (long i = 0; i < s->m + n; ++i) {
            if (i < s->m ? !s->rows[i] : !s->held_x[i - s->m]) continue;
            double *row = s->Cm + h * n, norm = norms[h];
            if (norm > 0 && i < s->m)
                for (long j = 0; j < n; ++j) row[j] = (weight / norm) * (s->A[i * n + j] / norm);
            else {
                memset(row, 0, n * sizeof(double));
                if (norm > 0) row[i - s->m] = weight / norm;
            }
            ++h;
        }
        s->k_C = h;
        s->modified = 1;
        return 1;
    }
    return 0;
}

/* c̃ = S ∇f, Ã = J S of it */
static void linear_model(Sqp *s, It it) {
    long n = s->n;
    for (long j = 0; j < n; ++j) s->c[j] = it.grad[j] * s->scale[j];
    for (long i = 0; i < s->m; ++i)
        for (long j = 0; j < n; ++j) s->A[i * n + j] = it.J[i * n + j] * s->scale[j];
}

/* model_at: ∇²L at it in the scaled variables, S H S + δ I when positive definite, else
   hessian.convexified's τ ladder (:func:`augmented`), else Python's hessian.by_eigenvalues; the
   rows held (equalities and rows with a multiplier) and the bounds held (a multiplier of their
   own). Returns 0, or -1 when Python failed. */
static long model_at(Sqp *s, It it) {
    long n = s->n;
    for (long i = 0; i < s->m; ++i) s->rows[i] = s->equal[i] || s->lam_g[i] != 0.0;
    for (long j = 0; j < n; ++j) s->held_x[j] = s->lam_x[j] != 0.0;
    linear_model(s, it);
    hessian(s, it.x, s->lam_g);
    double hs_max = 0.0;
    for (long i = 0; i < n; ++i)
        for (long j = 0; j < n; ++j) {
            double v = s->H[i * n + j] * (s->scale[i] * s->scale[j]);
            s->B[i * n + j] = v;
            hs_max = nmax(hs_max, fabs(v));
        }
    for (long j = 0; j < n; ++j) s->B[j * n + j] += s->delta;
    s->model_version += 1;
    s->k_C = 0;
    if (positive(s, s->B)) {
        s->modified = 0;
        return 0;
    }
    if (augmented(s, hs_max)) return 0;
    return s->ask(ASK_MODEL) ? -1 : 0;
}

/* model.damped_bfgs on B̃ in place along sv with y */
static void damped_bfgs(Sqp *s, const double *sv, const double *y) {
    long n = s->n;
    double *B = s->B, *Bs = s->w3, *r = s->w4, *W = s->wnn;
    for (long i = 0; i < n; ++i) {
        double acc = 0.0;
        for (long j = 0; j < n; ++j) acc += B[i * n + j] * sv[j];
        Bs[i] = acc;
    }
    double sBs = 0.0, sy = 0.0;
    for (long j = 0; j < n; ++j) sBs += sv[j] * Bs[j];
    if (sBs <= 1e-300) return;
    for (long j = 0; j < n; ++j) sy += sv[j] * y[j];
    double theta = sy >= 0.2 * sBs ? 1.0 : 0.8 * sBs / (sBs - sy);
    double sr = 0.0;
    for (long j = 0; j < n; ++j) {
        r[j] = theta * y[j] + (1 - theta) * Bs[j];
        sr += sv[j] * r[j];
    }
    double top = 0.0;
    for (long i = 0; i < n; ++i)
        for (long j = 0; j < n; ++j) {
            double v = (B[i * n + j] - Bs[i] * Bs[j] / sBs) + r[i] * r[j] / sr;
            W[i * n + j] = v;
            top = nmax(top, fabs(v));
        }
    if (top <= s->curvature_max) memcpy(B, W, n * n * sizeof(double));
}

/* relinearized: B̃ updated along the step from prev to it, c̃ and Ã of it */
static void relinearized(Sqp *s, It prev, It it) {
    long n = s->n;
    double *sv = s->w1, *y = s->w2;
    for (long j = 0; j < n; ++j) sv[j] = (it.x[j] - prev.x[j]) / s->scale[j];
    double *a = s->w3, *b = s->w4;
    jt_times(s, it.J, s->lam_g, a);
    jt_times(s, prev.J, s->lam_g, b);
    for (long j = 0; j < n; ++j) y[j] = s->scale[j] * ((it.grad[j] + a[j]) - (prev.grad[j] + b[j]));
    damped_bfgs(s, sv, y);
    linear_model(s, it);
    s->k_C = 0;
    s->model_version += 1;
}

/* _qp: the region's bounds in the scaled variables and the rows' */
static void qp_bounds(Sqp *s, It it, double radius) {
    for (long j = 0; j < s->n; ++j) {
        s->lb[j] = nmax((s->lbx[j] - it.x[j]) / s->scale[j], -radius);
        s->ub[j] = nmin((s->ubx[j] - it.x[j]) / s->scale[j], radius);
    }
    for (long i = 0; i < s->m; ++i) {
        s->lbA[i] = s->lbg[i] - it.g[i];
        s->ubA[i] = s->ubg[i] - it.g[i];
    }
}

/* _Promise.of: ‖viol(g + J d)‖₁ (rows within linear_tol counted as holding), ∇fᵀd, ½dᵀBd */
typedef struct { double violation, slope, curvature; } Promise;

static Promise promise_of(Sqp *s, It it, const double *d) {
    long n = s->n, m = s->m;
    Promise p = {0.0, 0.0, 0.0};
    double *v = s->wm;
    for (long i = 0; i < m; ++i) {
        double acc = 0.0;
        const double *row = it.J + i * n;
        for (long j = 0; j < n; ++j) acc += row[j] * d[j];
        v[i] = it.g[i] + acc;
    }
    violation(s, v, v);
    for (long i = 0; i < m; ++i)
        if (v[i] > s->linear_tol) p.violation += v[i];
    for (long j = 0; j < n; ++j) p.slope += it.grad[j] * d[j];
    double *ds = s->w1, *vb = s->w2;
    for (long j = 0; j < n; ++j) ds[j] = d[j] / s->scale[j];
    for (long j = 0; j < n; ++j) {
        double acc = 0.0;
        for (long i = 0; i < n; ++i) acc += ds[i] * s->B[i * n + j];
        vb[j] = acc;
    }
    double q = 0.0;
    for (long j = 0; j < n; ++j) q += vb[j] * ds[j];
    p.curvature = 0.5 * q;
    return p;
}

static double reduction(Promise p, It it, double penalty) {
    return penalty * (*it.l1 - p.violation) - p.slope - p.curvature;
}

/* _steered */
static double steered(It it, Promise p, double penalty, double penalty_max) {
    double dv = *it.l1 - p.violation, q = p.slope + p.curvature;
    if (dv > 1e-14 && q > 0) penalty = fmax(penalty, q / (0.5 * dv));
    return fmin(penalty, penalty_max);
}

/* model.corrected: the multipliers of a QP on a convexified B̃ made the program's */
static void corrected(Sqp *s) {
    long n = s->n;
    if (s->k_C == 0) return;
    double *ds = s->w1, *extra = s->wm;
    for (long j = 0; j < n; ++j) ds[j] = s->d[j] / s->scale[j];
    for (long k = 0; k < s->k_C; ++k) {
        double acc = 0.0;
        for (long j = 0; j < n; ++j) acc += s->Cm[k * n + j] * ds[j];
        extra[k] = acc;
    }
    long k = 0;
    for (long i = 0; i < s->m; ++i) {
        if (!s->rows[i]) continue;
        if (s->lam_r[i] != 0.0 || s->equal[i]) s->lam_r[i] += extra[k];
        ++k;
    }
    for (long j = 0; j < n; ++j) {
        if (!s->held_x[j]) continue;
        if (s->lam_b[j] != 0.0) s->lam_b[j] += extra[k] / s->scale[j];
        ++k;
    }
}

/* _own_bound_multipliers into lam_x */
static void own_bound_multipliers(Sqp *s, It it) {
    for (long j = 0; j < s->n; ++j) {
        double l = s->lam_b[j];
        int lower = it.x[j] <= s->lbx[j] + 1e-12 && l < 0;
        int upper = it.x[j] >= s->ubx[j] - 1e-12 && l > 0;
        s->lam_x[j] = (lower || upper) ? l : 0.0;
    }
}

/* _step: the step's QP (Python: relaxed, else elastic), unscaled, its promise, the penalty
   it needs, its multipliers corrected. Returns 1 solved, 0 no step, -1 Python failed. */
static long step(Sqp *s, It it, double *penalty, Promise *p) {
    long n = s->n, m = s->m;
    s->penalty = *penalty;
    if (s->ask(ASK_STEP)) return -1;
    for (long j = 0; j < n; ++j) {
        s->d[j] = s->qd[j] * s->scale[j];
        s->lam_b[j] = s->qlb[j] / s->scale[j];
    }
    memcpy(s->lam_r, s->qlr, m * sizeof(double));
    if (s->q_solved) {
        if (!s->q_elastic) {
            memcpy(s->duals, s->lam_b, n * sizeof(double));
            memcpy(s->duals + n, s->lam_r, m * sizeof(double));
            s->has_duals = 1;
        }
        *p = promise_of(s, it, s->d);
        *penalty = s->q_elastic ? s->penalty : steered(it, *p, *penalty, s->penalty_max);
    } else if (s->q_elastic) {
        *penalty = s->penalty;
    }
    s->qp_iterations += s->q_iters;
    if (!s->q_solved) return 0;
    corrected(s);
    for (long i = 0; i < m; ++i) s->rows_bound[i] |= s->lam_r[i] != 0.0;
    return 1;
}

/* trial.x = clip(it.x + d), evaluated; the merit's ratio actual / predicted */
static double trial_ratio(Sqp *s, It it, It trial, const double *d, double penalty,
                          double merit0, double pred) {
    double *a = s->w2;
    for (long j = 0; j < s->n; ++j) a[j] = it.x[j] + d[j];
    clipped(s, a, trial.x);
    evaluate(s, trial);
    return (merit0 - *trial.f - penalty * *trial.l1) / pred;
}

/* _try_step: 1 taken (trial holds the next iterate, *ratio its ratio), 0 rejected, -1 Python
   failed */
static long try_step(Sqp *s, It it, It trial, double penalty, Promise p, double *ratio) {
    long n = s->n, m = s->m;
    double pred = reduction(p, it, penalty);
    double merit0 = *it.f + penalty * *it.l1;
    if (pred <= 1e-16 * fmax(1.0, fabs(merit0))) return 0;
    *ratio = trial_ratio(s, it, trial, s->d, penalty, merit0, pred);
    if (*ratio >= s->eta) return 1;
    /* the second-order correction: the rows shifted by their curvature along d */
    for (long i = 0; i < m; ++i) {
        double acc = 0.0;
        const double *row = it.J + i * n;
        for (long j = 0; j < n; ++j) acc += row[j] * s->d[j];
        double shift = (trial.g[i] - it.g[i]) - acc;
        s->soc_lbA[i] = s->lbA[i] - shift;
        s->soc_ubA[i] = s->ubA[i] - shift;
    }
    memcpy(s->soc_duals, s->lam_b, n * sizeof(double));
    memcpy(s->soc_duals + n, s->lam_r, m * sizeof(double));
    if (s->ask(ASK_SOC)) return -1;
    if (!s->q_solved) return 0;
    double *d2 = s->w3;
    for (long j = 0; j < n; ++j) d2[j] = s->qd[j] * s->scale[j];
    *ratio = trial_ratio(s, it, trial, d2, penalty, merit0, pred);
    return *ratio >= s->eta ? 1 : 0;
}

/* _Flat.settled over the ring of the last flat_iterations costs */
static int settled(Sqp *s, It it, long *count) {
    if (*it.worst > s->tol_primal) {
        *count = 0;
        return 0;
    }
    s->costs[*count % s->flat_iterations] = *it.f;
    *count += 1;
    if (*count < s->flat_iterations) return 0;
    double lo = s->costs[0], hi = s->costs[0];
    for (long k = 1; k < s->flat_iterations; ++k) {
        lo = nmin(lo, s->costs[k]);
        hi = nmax(hi, s->costs[k]);
    }
    return hi - lo <= s->flat_change * fmax(1.0, fabs(*it.f));
}

/* sqp: the run from X[cur] (inside the bounds), lam_g, lam_x and duals (has_duals) as
   given; returns its status (also in s->status) */
long sqp_run(Sqp *s) {
    double t0 = now();
    long n = s->n, m = s->m;
    It it = slot(s, s->cur);
    evaluate(s, it);
    double radius = s->radius0, penalty = s->penalty0, ratio = 0.0;
    double stall_best = *it.l1;
    long stall_since = 0, kept = 0, flat_count = 0, have_model = 0, ended = 0;
    Promise p;
    s->status = UNFINISHED;
    for (long iter = 0; iter < s->max_iter; ++iter) {
        for (long i = 0; i < m; ++i) s->rows_bound[i] |= it.viol[i] > 0;
        /* _stop */
        if (converged(s, it, s->lam_g, s->lam_x)) { s->status = SUCCEEDED; ended = 1; break; }
        if (now() - t0 > s->max_time_s) { s->status = CPU_TIME; ended = 1; break; }
        if (*it.l1 < 0.99 * stall_best || *it.l1 <= s->tol_primal) {
            stall_best = fmin(stall_best, *it.l1);
            stall_since = 0;
        } else if (++stall_since >= s->stall_iterations) {
            s->status = INFEASIBLE; ended = 1; break;
        }
        if (!have_model) {
            if (model_at(s, it)) { s->status = ASK_FAILED; ended = 1; break; }
            kept = 0;
            have_model = 1;
            s->modified_hessians += s->modified;
        }
        s->iterations += 1;
        qp_bounds(s, it, radius);
        long solved = step(s, it, &penalty, &p);
        if (solved < 0) { s->status = ASK_FAILED; ended = 1; break; }
        if (!solved) { s->status = STEP_ERROR; ended = 1; break; }
        double d_size = 0.0;
        for (long j = 0; j < n; ++j) d_size = nmax(d_size, fabs(s->d[j]) / s->scale[j]);
        if (d_size < 1e-12) { /* _standing */
            memcpy(s->lam_g, s->lam_r, m * sizeof(double));
            own_bound_multipliers(s, it);
            s->status = converged(s, it, s->lam_g, s->lam_x) ? SUCCEEDED : stalled(s, it);
            if (s->status == SUCCEEDED || !kept) { ended = 1; break; }
            have_model = 0;
            s->status = UNFINISHED;
            continue;
        }
        double *h = s->history + 3 * s->history_len++;
        h[0] = *it.f; h[1] = *it.worst; h[2] = radius;
        It trial = slot(s, 1 - s->cur);
        long taken = try_step(s, it, trial, penalty, p, &ratio);
        if (taken < 0) { s->status = ASK_FAILED; ended = 1; break; }
        if (!taken) { /* _shrunk */
            radius = s->shrink * fmin(radius, d_size);
            int fresh = 0;
            if (radius < s->radius_min && kept) { radius = s->radius0; fresh = 1; }
            if (radius < s->radius_min) { s->status = stalled(s, it); ended = 1; break; }
            if (fresh) have_model = 0;
            continue;
        }
        It previous = it;
        s->cur = 1 - s->cur;
        it = trial;
        memcpy(s->lam_g, s->lam_r, m * sizeof(double));
        own_bound_multipliers(s, it);
        /* ν down to PENALTY_OVER_MULTIPLIERS × ‖λ‖∞, not below ν0 (fmin ignores a NaN as
           Python's min does) */
        penalty = fmax(s->penalty0, fmin(penalty, s->penalty_over * max_abs(s->lam_g, m)));
        kept += 1;
        if (kept < s->hessian_every) relinearized(s, previous, it);
        else have_model = 0;
        if (settled(s, it, &flat_count) && !converged(s, it, s->lam_g, s->lam_x)) {
            s->status = ACCEPTABLE; ended = 1; break;
        }
        if (ratio > 0.75 && d_size >= 0.99 * radius) radius = fmin(2.0 * radius, s->radius_max);
    }
    if (!ended && converged(s, it, s->lam_g, s->lam_x)) s->status = SUCCEEDED;
    s->wall_s = now() - t0;
    return s->status;
}
