/* The compiled floor of the fast backend's per-step work (mdgran/backends/fast_kernel.py,
 * verlet_pass with locate = True): velocity Verlet with the predicted end velocity for the
 * damping force, nearest-neighbour contact forces (the cubic spline table in
 * w = sqrt(delta - base) of mdgran.model.contact.ContactTable, or Hertz delta^1.5), open/closed
 * states with the locate filter test (flags counted, not located), substrate k1, one-sided
 * damping, the damping power sum; two alternating buffers of (x, v, a) as the kernel has.
 *
 * Usage: floor STATE_FILE STEPS REPEATS [OUT_FILE]
 *   STATE_FILE: written by benchmarks/kernel_floor.py (dump_state): the run's constants, the
 *               table and the state (x, v, a, closed) after the backend's initial settle.
 *   Runs STEPS steps REPEATS times, each from the state of the end of the previous one, and
 *   prints one JSON line: per repeat the CPU time and wall time in ns per bead-step, the flags
 *   counted and the kick tests taken; OUT_FILE (optional) gets x, v, a after the first repeat
 *   and the sums (D_viscous, power) for the trajectory check.
 * Build: cc -O2 -o floor floor.c -lm
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

typedef struct {
    int64_t n, m, walls, damped, k1_on, hertz, rows;
    double gap, c, k1, doff, delta_max, mfb, base, scale, last, step, power;
    double vh_l; /* scratch of pass_blocked */
} Header;

typedef struct {
    double *x, *v, *a;
} Buf;

typedef struct {
    int64_t flagged, kicks, out_of_table;
} Counts;

static const double *COEF; /* [rows][4], highest power first */

/* Unlike beads (the kernel's flags.mixed, mdgran.backends.fast_kernel.Mix): contact j is of
 * kind KIND[j], whose row PAIR + NPAIR * KIND[j] holds its constants (fields P_* as the
 * kernel's PAIR_FIELDS), its class's cubics in MCOEF from row[P_FIRST] on. */
enum { P_SCALE, P_INV_LEN, P_LEN, P_OFF, P_BASE, P_WSCALE, P_STEP, P_BELOW, P_FIRST,
       P_INV_MASS, P_ON_SITE, NPAIR };
static const uint32_t *KIND;
static const double *PAIR, *MCOEF;

/* The table force at table coordinate w (0 <= w < last): Horner on the cubic of floor(w). */
static inline double spline(double w, double step) {
    int64_t i = (int64_t)w;
    double x = (w - (double)i) * step;
    const double *c = COEF + 4 * i;
    return ((c[0] * x + c[1]) * x + c[2]) * x + c[3];
}

/* One Verlet pass of length h from `o` into `nw`; returns the damping power at the end.
 * Inlined into `pass` with the scene's terms as constants (as numba's compiled variants
 * have them), so an absent term costs nothing in the loop.  `mixed`: unlike beads, as the
 * kernel's mixed variant: the contact's row read through its kind, its own units
 * u = delta / L, F = A f(u), the mean-force test in its class's band, the left bead's
 * acceleration times its 1 / m (table law only). */
static inline __attribute__((always_inline)) double pass_of(
    const Header *P, const uint8_t *closed, Buf o, Buf nw, double h, Counts *cnt,
    const int walls, const int hertz, const int damped, const int k1_on, const int mixed) {
    const int64_t n = P->n, m = P->m;
    const double hh = 0.5 * h, gap = P->gap, c = P->c, k1 = P->k1, doff = P->doff;
    const double base = P->base, scale = P->scale, last = P->last, step = P->step;
    const double mfb = P->mfb, dmax = P->delta_max;
    double power = 0.0, x_c = 0.0, vh_c = 0.0, ve_c = 0.0, f_l = 0.0, fv_l = 0.0;
    int64_t nflag = 0, kicks = 0, bad = 0;
    if (!walls) {
        vh_c = o.v[0] + hh * o.a[0];
        x_c = o.x[0] + h * vh_c;
        ve_c = vh_c + hh * o.a[0];
    }
    const int64_t rshift = walls ? 0 : 1;
    for (int64_t j = 0; j < m; j++) {
        int64_t rb = j + rshift;
        double x_r = 0.0, vh_r = 0.0, ve_r = 0.0;
        if (rb < n) {
            double a_r = o.a[rb];
            vh_r = o.v[rb] + hh * a_r;
            x_r = o.x[rb] + h * vh_r;
            ve_r = vh_r + hh * a_r;
        }
        double d = x_c - x_r - gap;
        double r = ve_c - ve_r;
        double f_r = 0.0, fv_r = 0.0, g, gd, d_off = doff, im = 1.0;
        const double *row = PAIR;
        if (mixed) {
            row = PAIR + (uint64_t)NPAIR * KIND[j];
            d_off = row[P_OFF];
            im = row[P_INV_MASS];
        }
        if (closed[j]) {
            if (mixed) {
                double u = d * row[P_INV_LEN] - row[P_BASE];
                if (u < 0.0) u = 0.0;
                double w = sqrt(u) * row[P_WSCALE];
                if (w < last) {
                    int64_t i = (int64_t)w;
                    double x = (w - (double)i) * row[P_STEP];
                    const double *cf = MCOEF + (uint64_t)row[P_FIRST] + 4 * i;
                    f_r = row[P_SCALE] * (((cf[0] * x + cf[1]) * x + cf[2]) * x + cf[3]);
                } else
                    bad++;
            } else if (hertz) {
                if (!(d < dmax)) bad++;
                double dp = d < 0.0 ? 0.0 : d;
                f_r = dp * sqrt(dp);
            } else {
                double u = d - base;
                if (u < 0.0) u = 0.0;
                double w = sqrt(u) * scale;
                if (w < last) f_r = spline(w, step);
                else bad++;
            }
            fv_r = f_r;
            /* the kernel's mean-force kick: counted, not taken */
            if (mixed ? d * row[P_INV_LEN] < row[P_BELOW] : d < mfb) kicks++;
            if (damped) {
                f_r += c * r;
                fv_r += c * r;
                power += c * r * r;
            }
            g = d - d_off;
            gd = r;
        } else {
            g = -d;
            gd = -r;
        }
        if (g < 0.0 || g < 0.5 * h * gd) nflag++;
        if (rb >= 1) {
            double a = f_l - f_r, av = fv_l - fv_r;
            if (k1_on) {
                a -= k1 * x_c;
                av -= k1 * x_c;
            }
            nw.x[rb - 1] = x_c;
            nw.a[rb - 1] = mixed ? a * im : a;
            nw.v[rb - 1] = vh_c + hh * (mixed ? av * im : av);
        }
        x_c = x_r, vh_c = vh_r, ve_c = ve_r;
        f_l = f_r, fv_l = fv_r;
    }
    if (!walls) {
        double a = f_l, av = fv_l;
        if (k1_on) {
            a -= k1 * x_c;
            av -= k1 * x_c;
        }
        nw.x[n - 1] = x_c;
        nw.a[n - 1] = a;
        nw.v[n - 1] = vh_c + hh * av;
    }
    cnt->flagged += nflag;
    cnt->kicks += kicks;
    cnt->out_of_table += bad;
    return power;
}


/* The same pass in blocks of BLOCK contacts, each in three loops the compiler can vectorize
 * (no branch, no loop-carried value): predict the beads, the contact forces (open contacts
 * get 0 through a select), the beads' ends; the power sum and the flag test stay in contact
 * order (the sum's rounding is that of the fused pass).  Same operations per element as
 * pass_of: bitwise the same results.  Walls, table law only (the variant timed). */
#define BLOCK 256
static double pass_blocked(const Header *P, const uint8_t *closed, Buf o, Buf nw, double h,
                           Counts *cnt) {
    const int64_t n = P->n, m = P->m;
    const double hh = 0.5 * h, gap = P->gap, c = P->c, k1 = P->k1, doff = P->doff;
    const double base = P->base, scale = P->scale, last = P->last, step = P->step;
    const double mfb = P->mfb;
    double xp[BLOCK + 1], vh[BLOCK + 1], ve[BLOCK + 1], f[BLOCK + 1], pw[BLOCK], g[BLOCK],
        gd[BLOCK];
    double power = 0.0;
    int64_t nflag = 0, kicks = 0, bad = 0;
    double f_l = 0.0; /* force of the contact left of the block's first bead */
    double x_l = 0.0, ve_l = 0.0; /* bead left of the block's first contact (the wall) */
    /* contact j (0..m-1) is between beads j-1 and j; block [j0, j0+len) ends beads j0..j0+len-2 */
    for (int64_t j0 = 0; j0 < m; j0 += BLOCK) {
        int64_t len = m - j0 < BLOCK ? m - j0 : BLOCK;
        /* beads j0 .. j0+len-1 (those < n) predicted; xp[k] = bead j0+k */
        int64_t nb = j0 + len <= n ? len : n - j0;
        for (int64_t k = 0; k < nb; k++) {
            double a = o.a[j0 + k];
            double v = o.v[j0 + k] + hh * a;
            vh[k] = v;
            xp[k] = o.x[j0 + k] + h * v;
            ve[k] = v + hh * a;
        }
        for (int64_t k = nb; k < len; k++) xp[k] = vh[k] = ve[k] = 0.0; /* the right wall */
        int any = 0;
        for (int64_t k = 0; k < len; k++) {
            double xl = k ? xp[k - 1] : x_l, vl = k ? ve[k - 1] : ve_l;
            double d = xl - xp[k] - gap, r = vl - ve[k];
            double u = d - base;
            u = u < 0.0 ? 0.0 : u;
            double w = sqrt(u) * scale;
            int ok = w < last;
            double wc = ok ? w : 0.0;
            int64_t i = (int64_t)wc;
            double x = (wc - (double)i) * step;
            const double *cf = COEF + 4 * i;
            double fs = ((cf[0] * x + cf[1]) * x + cf[2]) * x + cf[3];
            int cl = closed[j0 + k];
            f[k] = cl ? fs + c * r : 0.0;
            pw[k] = cl ? c * r * r : 0.0;
            g[k] = cl ? d - doff : -d;
            gd[k] = cl ? r : -r;
            any |= cl & ((!ok) | (d < mfb));
        }
        if (any) { /* rare: out of the table or a mean-force kick */
            for (int64_t k = 0; k < len; k++) {
                double xl = k ? xp[k - 1] : x_l;
                double d = xl - xp[k] - gap;
                if (closed[j0 + k]) {
                    double w = sqrt(d - base < 0.0 ? 0.0 : d - base) * scale;
                    bad += !(w < last);
                    kicks += d < mfb;
                }
            }
        }
        for (int64_t k = 0; k < len; k++) {
            power += pw[k];
            if (g[k] < 0.0 || g[k] < 0.5 * h * gd[k]) nflag++;
        }
        /* beads j0-1 .. j0+len-2: bead b has contacts b (left) and b+1 (right) */
        for (int64_t k = 0; k < len; k++) {
            int64_t b = j0 + k - 1;
            if (b < 0) continue;
            double fl = k ? f[k - 1] : f_l;
            double xb = k ? xp[k - 1] : x_l, vb = k ? vh[k - 1] : 0.0;
            if (!k) vb = P->vh_l;
            double a = (fl - f[k]) - k1 * xb;
            nw.x[b] = xb;
            nw.a[b] = a;
            nw.v[b] = vb + hh * a;
        }
        f_l = f[len - 1];
        x_l = xp[len - 1];
        ve_l = ve[len - 1];
        ((Header *)P)->vh_l = vh[len - 1];
    }
    cnt->flagged += nflag;
    cnt->kicks += kicks;
    cnt->out_of_table += bad;
    return power;
}

/* The pass of the scene's variant (damping and k1 constant where the scene has them on). */
static int BLOCKED = 0;
static double pass(const Header *P, const uint8_t *closed, Buf o, Buf nw, double h, Counts *cnt) {
    if (BLOCKED) return pass_blocked(P, closed, o, nw, h, cnt);
    if (KIND) return pass_of(P, closed, o, nw, h, cnt, 1, 0, 1, 1, 1);
    if (P->damped && P->k1_on) {
        if (P->walls)
            return P->hertz ? pass_of(P, closed, o, nw, h, cnt, 1, 1, 1, 1, 0)
                            : pass_of(P, closed, o, nw, h, cnt, 1, 0, 1, 1, 0);
        return P->hertz ? pass_of(P, closed, o, nw, h, cnt, 0, 1, 1, 1, 0)
                        : pass_of(P, closed, o, nw, h, cnt, 0, 0, 1, 1, 0);
    }
    return pass_of(P, closed, o, nw, h, cnt, P->walls, P->hertz, P->damped, P->k1_on, 0);
}

static void read_all(FILE *f, void *p, size_t size, size_t count) {
    if (fread(p, size, count, f) != count) {
        fprintf(stderr, "floor: short state file\n");
        exit(2);
    }
}

static double now(clockid_t id) {
    struct timespec ts;
    clock_gettime(id, &ts);
    return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

int main(int argc, char **argv) {
    if (argc < 4) {
        fprintf(stderr, "usage: floor STATE_FILE STEPS REPEATS [OUT_FILE]\n");
        return 2;
    }
    FILE *f = fopen(argv[1], "rb");
    if (!f) {
        perror(argv[1]);
        return 2;
    }
    Header P;
    double h;
    read_all(f, &P.n, sizeof(int64_t), 7);
    read_all(f, &h, sizeof(double), 1);
    read_all(f, &P.gap, sizeof(double), 11);
    const int64_t n = P.n, m = P.m;
    double *coef = malloc(sizeof(double) * 4 * (P.rows > 0 ? P.rows : 1));
    read_all(f, coef, sizeof(double), 4 * P.rows);
    COEF = coef;
    double *mem = malloc(sizeof(double) * 6 * n);
    Buf b[2] = {{mem, mem + n, mem + 2 * n}, {mem + 3 * n, mem + 4 * n, mem + 5 * n}};
    read_all(f, b[0].x, sizeof(double), n);
    read_all(f, b[0].v, sizeof(double), n);
    read_all(f, b[0].a, sizeof(double), n);
    uint8_t *closed = malloc(m);
    read_all(f, closed, 1, m);
    int64_t kinds_rows[2]; /* optional trailer (unlike beads): kinds, coefficients */
    if (fread(kinds_rows, sizeof(int64_t), 2, f) == 2) {
        uint32_t *kind = malloc(sizeof(uint32_t) * m);
        double *pair = malloc(sizeof(double) * NPAIR * kinds_rows[0]);
        double *mcoef = malloc(sizeof(double) * kinds_rows[1]);
        read_all(f, kind, sizeof(uint32_t), m);
        read_all(f, pair, sizeof(double), NPAIR * kinds_rows[0]);
        read_all(f, mcoef, sizeof(double), kinds_rows[1]);
        KIND = kind, PAIR = pair, MCOEF = mcoef;
        if (!P.walls || P.hertz || !P.damped || !P.k1_on) {
            fprintf(stderr, "floor: the mixed pass is for walls, table law, damping, k1\n");
            return 2;
        }
    }
    fclose(f);
    memcpy(b[1].x, b[0].x, sizeof(double) * 3 * n); /* touch the second buffer */
    const long steps = atol(argv[2]), repeats = atol(argv[3]);
    BLOCKED = getenv("FLOOR_BLOCKED") != NULL;
    if (BLOCKED && (!P.walls || P.hertz || !P.damped || !P.k1_on)) {
        fprintf(stderr, "floor: the blocked pass is for walls, table law, damping, k1\n");
        return 2;
    }
    int cur = 0;
    double power = P.power, d_visc = 0.0;
    Counts cnt = {0, 0, 0};
    printf("{\"n\": %ld, \"steps\": %ld, \"cpu_ns\": [", (long)n, steps);
    double *wall_ns = malloc(sizeof(double) * repeats);
    for (long k = 0; k < repeats; k++) {
        double c0 = now(CLOCK_PROCESS_CPUTIME_ID), w0 = now(CLOCK_MONOTONIC);
        for (long s = 0; s < steps; s++) {
            double p1 = pass(&P, closed, b[cur], b[1 - cur], h, &cnt);
            d_visc += 0.5 * h * (power + p1);
            power = p1;
            cur = 1 - cur;
        }
        double c1 = now(CLOCK_PROCESS_CPUTIME_ID), w1 = now(CLOCK_MONOTONIC);
        wall_ns[k] = (w1 - w0) / ((double)n * steps) * 1e9;
        printf("%s%.4f", k ? ", " : "", (c1 - c0) / ((double)n * steps) * 1e9);
        if (k == 0 && argc > 4) {
            FILE *o = fopen(argv[4], "wb");
            fwrite(b[cur].x, sizeof(double), n, o);
            fwrite(b[cur].v, sizeof(double), n, o);
            fwrite(b[cur].a, sizeof(double), n, o);
            fwrite(&d_visc, sizeof(double), 1, o);
            fwrite(&power, sizeof(double), 1, o);
            fclose(o);
        }
    }
    printf("], \"wall_ns\": [");
    for (long k = 0; k < repeats; k++) printf("%s%.4f", k ? ", " : "", wall_ns[k]);
    printf("], \"flagged\": %ld, \"kicks\": %ld, \"out_of_table\": %ld}\n", (long)cnt.flagged,
           (long)cnt.kicks, (long)cnt.out_of_table);
    return 0;
}
