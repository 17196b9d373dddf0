// mdgran: fix mdgran/chain, the hysteretic contact of a 1-D bead chain (see the .cpp file).
#ifndef LMP_FIX_MDGRAN_CHAIN_H
#define LMP_FIX_MDGRAN_CHAIN_H

#include "fix.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>
#include <vector>

namespace LAMMPS_NS {

// One contact law in its own units (mdgran/model/contact.py's ContactLaw and ContactTable): the
// chain's law, and with "mixture" the law of each class of unlike pairs.
struct MdgranLaw {
  int hertz = 0;                            // 1: f = delta_+^(3/2); 0: Schwarz
  double fc = 0.0, sigma = 0.0, tm = 0.0, big = 0.0, sqrt_big = 0.0, delta_min = 0.0;
  double delta_off = 0.0, t0 = 0.0;
  double p_t0 = 0.0;                        // P(t0): V(delta) = P(t(delta)) - P(t0)
  int strict = 0;                           // delta_off == 0: strict inequalities
  double sing = -INFINITY;                  // located: mean-force kick below this delta
  // spline table in w = sqrt(delta - base) (mdgran.model.contact.ContactTable), optional
  int use_table = 0, tab_n = 0;
  double tab_base = 0.0, tab_scale = 0.0, tab_h = 0.0, tab_delta_max = 0.0;
  std::vector<double> tab_coef;             // (n - 1) x 4, highest power first

  void set(int hertz_law, double fc_law, int snap_force);    // the constants of contact.py
  std::string read_table(const char *file);    // "" or what is wrong
  double law_force(double delta) const;     // attached branch, exact (Newton) or table
  double mean_force(double d0, double d1) const;    // (V(d1) - V(d0)) / (d1 - d0), Schwarz
  double mean_force_t(double t0, double t1) const;  // the same from t(d0), t(d1)
  double law_energy(double delta) const;    // V(delta) on the attached branch, exact
  double exact_force(double delta) const;
  // cubic spline in w = sqrt(delta - base), as ContactTable.force (Horner, highest power first)
  inline double spline_force(double d) const
  {
    double w = std::sqrt(std::max(d - tab_base, 0.0));
    double s = std::min(w * tab_scale, (double) (tab_n - 1) - 1e-9);
    long i = (long) s;
    double x = (s - (double) i) * tab_h;
    const double *c = &tab_coef[4 * i];
    return ((c[0] * x + c[1]) * x + c[2]) * x + c[3];
  }
  // f(delta) of a closed contact in located mode: Hertz exact (cheaper than the table and free
  // of its round-off force at delta = 0, which would make resting contacts flicker), else as set
  inline double located_force(double d) const
  {
    return (hertz || !use_table) ? exact_force(d) : spline_force(d);
  }
  double t_of_delta(double delta) const;
  void t_of_delta_n(const double *delta, double *t, int n) const;
  double antiderivative(double t) const;
};

// The chain's own law is its MdgranLaw base (the law's members and functions by their names).
class FixMdgranChain : public Fix, public MdgranLaw {
 public:
  FixMdgranChain(class LAMMPS *, int, char **);
  ~FixMdgranChain() override;
  int setmask() override;
  void init() override;
  void setup_pre_neighbor() override;
  void pre_neighbor() override;
  void setup(int) override;
  void initial_integrate(int) override;
  void final_integrate() override;
  void post_force(int) override;
  void post_run() override;

  double compute_scalar() override;
  double compute_vector(int) override;
  double compute_array(int, int) override;
  int copy_events(int first, int count, double *out);
  void drop_events(int end);

  void grow_arrays(int) override;
  void copy_arrays(int, int, int) override;
  int pack_exchange(int, double *) override;
  int unpack_exchange(int, double *) override;
  int pack_restart(int, double *) override;
  void unpack_restart(int, int) override;
  int size_restart(int) override;
  int maxsize_restart() override;
  void write_restart(FILE *) override;
  void restart(char *) override;
  int pack_forward_comm(int, int *, double *, int, int *) override;
  void unpack_forward_comm(int, int, double *) override;
  double memory_usage() override;

  // the contact law: MdgranLaw's (public: the unit test calls them through a tiny driver)

 private:
  int snap_force;                           // snap-off rule: 0 displacement, 1 force
  double damping, k1, k3, gap;
  double tether;                            // quantized: the linear substrate's K (0: none)
  int integrate;                            // quantized: the fix moves the atoms (fix nve's)
  void nve(int first);
  int walls;
  std::string table_file;

  // ---- unlike beads ("mixture FILE") and substrate damping ("sub_damping c") --------------
  // By tag (entry 0 unused): bead 1/mass and substrate factor g, and for the contact whose
  // left atom has the tag its scales A, 1/L, L (F = A f(delta / L), V = A L V(delta / L)),
  // threshold L delta_off and law class.  extended: either is set (else none is read).
  int mixed, extended;
  double sub_damping;
  std::vector<double> m_inv_mass, m_on_site, m_scale, m_inv_len, m_length, m_delta_off;
  std::vector<int> m_cls;
  std::vector<MdgranLaw> laws;              // the classes' laws, own units
  void read_mixture(const char *file);
  double mixed_force(tagint jt, double d, int located_law) const;
  double mixed_energy(tagint jt, double d) const;
  struct Con;
  double mixed_located(const Con &c, double d, double h, double &F, double &Fv) const;
  inline double off_of(tagint jt) const { return mixed ? m_delta_off[jt] : delta_off; }

  // ---- excitations ("pulse TAG A T t0", "base FILE"; mdgran/model/drive.py) -----------------------
  // a half-sine force A sin(pi (t - t0) / T) on the atom with tag pulse_tag (0: none) for
  // t0 <= t <= t0 + T; the base motion u_b(t) under the substrate, cubics base_coef[4 k ..]
  // (highest power first, in t - k base_step; the last row after the samples), the substrate
  // then acting on u - u_b and w - u_b'.  driven: either is set (else none is read).
  int driven, pulse_tag, based;
  double pulse_amp, pulse_dur, pulse_start, base_step;
  std::vector<double> base_coef;
  double now_ub, now_vb, now_fp;            // located: u_b, u_b', F at the pass's time
  double work, work_all, work_prev;         // external work (this rank; all ranks; its rate)
  void read_base(const char *file);
  void drive_at(double t, double &ub, double &vb, double &fp) const;
  void set_drive_time(double t) { if (driven) drive_at(t, now_ub, now_vb, now_fp); }
  double external_power() const;

  // per-atom state, keyed by the atom: its initial x and the contact to its right
  double *x0;                               // initial x (displacement u = x - x0)
  double *closed;                           // 1.0 closed, 0.0 open (contact tag -> tag + 1)
  double *dprev;                            // that contact's delta at the previous step
  double *aprev;                            // the atom's acceleration at the previous step
                                            // (located: at the start of the step)
  double *xs, *vs;                          // located: x and v at the start of the step
  // scratch
  double *fcon;                             // force of the contact to the right
  double *u, *w;                            // displacement, velocity estimate
  int *left;                                // local index of the left neighbour (-1: none)
  double *fkick;                            // located: kick force of the contact to the right
  int nmax_scratch;
  void ensure_scratch();

  // step bookkeeping (as the Python hook)
  bigint last_step;
  int have_last;                            // a step was computed (delta_prev, acc_prev set)
  double power_prev;                        // damping power at the previous step (this rank)
  double d_hyst, d_visc;                    // this rank's dissipation since the start
  double d_hyst_all, d_visc_all;            // summed over ranks at the last sync
  bigint synced_step;                       // step of the last sync (several ranks)
  bigint ncompute, energy_at;               // force evaluations; the one energy_cache is for
  double energy_cache;                      // contact energy (thermo asks for it twice)

  struct Event {
    bigint step;
    tagint left;                            // tag of the contact's left atom
    int kind;                               // 1 close, 0 open
    double time;
  };
  std::vector<Event> ev_local;              // since the last sync, this rank
  std::vector<Event> ev_all;                // the events since ev_first, all ranks, in order
  bigint ev_first;                          // events released by drop_events (row numbers
                                            // of the global array stay those of every event)
  int event_rows() const { return (int) (ev_first + (bigint) ev_all.size()); }

  // ---- located events (events located): the fix integrates the chain itself --------------
  int located;                              // 1: events located inside the step; 0: quantized
  struct Con {
    int l, r, own;                          // local left and right atom; own: left is owned
  };
  std::vector<Con> cons;                    // contacts this rank evaluates
  std::vector<Con> gcons;                   // contacts between two ghosts (event windows)
  std::vector<Con> flagged;                 // contacts with a possible event in the pass
  struct Kick {
    int l;                                  // left atom of a contact in the mean-force band
    double d0, d, rate;                     // its compression at the pass's start and end
  };
  std::vector<Kick> kicks;                  // the pass's contacts in the band (one law)
  void finish_kicks();
  std::vector<int> runs;                    // owned atoms it moves, [begin, end) pairs
  std::vector<int> still;                   // the other owned atoms (walls, outside the group)
  std::vector<int> wall_atoms;              // walls among the owned and ghost atoms
  void build_contacts();
  int contacts_stale;                       // cons and left[] need rebuilding (re-neighboured)
  double drift_h;                           // h of the drift that left the owned atoms' u, w
                                            // for the next pass (-1: none)

  // ---- the activity front (section "the activity front" in the .cpp) ----------------------
  int front_known;                          // 0: the run's first step, every atom is stepped
  tagint front_lo, front_hi;                // the tags this rank steps (lo > hi: none)
  int front_all;                            // the front holds every owned atom: runs, cons
  std::vector<int> front_runs;              // else the owned moving atoms in it, as runs
  std::vector<int> front_cons;              // and the contacts the pass evaluates (cons index)
  std::vector<int> con_of;                  // cons index of the contact with left atom i (-1)
  std::vector<int> front_ids;               // scratch: the front's owned atoms
  tagint hull_lo, hull_hi;                  // first step: owned atoms not at rest at its start
  tagint moved_lo, moved_hi;                // every atom this rank changed or found moved
  double moved_all[2];                      // their hull over the ranks at the last sync
  double bead_steps, bead_steps_all;        // atoms stepped (this rank; all, at the last sync)
  double joins, joins_all;                  // event windows joined with one already stepped
  std::vector<int> ext_flags;               // extlist: which vector values are extensive
  void take_in_moved_state();
  int front_holds_still() const;
  void count_bead_steps();
  inline int rest_at(int i, const double *x, const double *v, int stride) const;
  void owned_hull(const double *x, const double *v, int stride, tagint &lo, tagint &hi) const;
  void select_front();
  void select_front_contacts();
  void widen_front_by_ghosts();
  void front_take_arrivals();
  void advance_front();
  inline const std::vector<int> &active_runs() const { return front_all ? runs : front_runs; }
  double located_pass(double h);
  template <bool MIX> double located_pass_t(double h);
  template <bool EXT> void accelerate_t(double h, int write_f);
  template <bool EXT>
  inline void bead_acc(int i, double fl, double fr, double fvl, double fvr, double ui,
                       double wi, double k1_, double k3_, double &a, double &av) const;
  void drift(double h);
  void accelerate(double h, int write_f);
  void located_step();
  void located_setup();
  double first_root(const Con &c, double h) const;
  void switch_contact(const Con &c, double time);
  void settle(std::vector<int> &list, double time);
  void add_visc(double dv);
  void add_event(tagint left, int kind, double time, double lost);
  inline double ustart(int i) const;         // displacement at the step start (walls: 0)
  inline double vstart(int i) const;         // velocity at the step start (walls: 0)
  inline double astart(int i) const;         // acceleration at the step start (walls: 0)
  inline int moves(int i) const;             // in the fix group and not a wall
  double closed_force(tagint t, double d) const;    // f of closed contact t (left tag) at d
  int in_band(tagint t, double d) const;    // mean-force kick band near snap-off
  double kick_force(tagint t, double d0, double d) const;    // 2 f_mean(d0, d) - f(d0)

  // ---- event windows (located_step; as the fast backend's local_events) -------------------
  // tags: a window is the beads lo .. hi; its neighbours lo - 1 and hi + 1 move on their
  // parabolas; slots hold the atoms with tags base .. base + n - 1 (lo - 2 .. hi + 2)
  struct Window {
    tagint lo, hi;
  };
  struct WinPass {                          // what a window sub-step found
    double power, f_left, f_right;          // this rank's damping power; edge contact forces
    int band;                               // edge contact closed in the kick band (1 l, 2 r)
  };
  struct Pending {                          // a switch in a window, logged once all are final
    int l, own, kind;                       // left atom, its owner is this rank, 1 close 0 open
    tagint left;
    double time, lost;
  };
  struct Out {                              // a window's end state of an owned atom
    int i;
    double x, v, a;
  };
  std::vector<Window> wins;
  std::vector<Pending> pending;
  std::vector<Out> wout;
  tagint wbase;                             // tag of slot 0
  std::vector<int> wi;                      // slot: local index (-1: beyond the chain)
  std::vector<double> wx0, wve;             // slot: x0; v_est of the sub-step in progress
  std::vector<double> wx[3], wv[3], wa[3];  // slot states: copies 0, 1 and the step start (2)
  std::vector<tagint> wswitch;              // contacts switching at a window's event
  std::vector<double> wroot;                // their roots (scratch)
  std::vector<std::pair<tagint, int>> chat; // chatter guard: switches per contact at chat_time
  double chat_time;
  tagint own_lo, own_hi, known_lo, known_hi;    // tags owned, and held contiguously around them
  std::vector<tagint> rank_ranges;          // those four of every rank (several ranks)
  void share_ranges();
  int window_visible(tagint lo, tagint hi) const;
  void window_writes(tagint lo, tagint hi, tagint &a, tagint &b) const;
  int window_writes_owned(tagint lo, tagint hi) const;
  void check_window_ranks(tagint lo, tagint hi) const;
  void find_windows(double h);
  void load_window(tagint lo, tagint hi);
  inline int slot(tagint t) const { return (int) (t - wbase); }
  inline int slot_wall(int k) const { return is_wall(wbase + k); }
  inline double slot_u(int c, int k) const { return slot_wall(k) ? 0.0 : wx[c][k] - wx0[k]; }
  inline int slot_mine(int k) const;        // slot k's atom is owned here
  double bead_power(int k, double ve) const;
  double window_power(int c, tagint lo, tagint hi) const;
  double window_external(int c, tagint lo, tagint hi) const;
  double start_force(int c, tagint t) const;
  void predict(int c, int k, double h, double &x, double &vh, double &ve) const;
  WinPass window_pass(int c, double h, double t1, tagint lo, tagint hi);
  void finish_bead(int n, int k, double fl, double fr, double fvl, double fvr, double h);
  int locate_window_events(int c, double h, double tol, tagint jl, tagint jr,
                           std::vector<tagint> &sw, double &te);
  double window_switch(int c, tagint t, double time);
  double window_settle(int c, const std::vector<tagint> &sw, double time);
  void pass_force(tagint t, double h, double &F, double &Fv) const;
  void finish_neighbour(tagint b, double h, double f_edge, double impulse, int window_left);
  int resolve_window(tagint lo, tagint hi, double t0, double dt, double &viscous,
                     double &power, double &work);
  void undo_pending(size_t mark);
  void widen(size_t k, int grow);
  void local_events(double t0, double dt, double &viscous, double &power, double &work);
  void commit_windows(int write_f);
  int forces_read() const;                  // LAMMPS's f is read at the end of this step
  // first element of a LAMMPS per-atom array of rows (x, v, f: one block, 3 per atom)
  static double *flat(double **a) { return a ? a[0] : nullptr; }

  void compute(bigint step);
  template <bool MIX> void compute_t(bigint step);
  void sync();
  tagint ntags;                             // atom->natoms: the last tag (a wall with walls)
  inline int is_wall(tagint t) const { return walls && (t == 1 || t == ntags); }
  inline double disp(int i) const;
  tagint contact_number(tagint left) const { return walls ? left : left + 1; }
};

}    // namespace LAMMPS_NS

#endif
