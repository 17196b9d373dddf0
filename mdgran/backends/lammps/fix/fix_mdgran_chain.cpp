// mdgran: fix mdgran/chain, the hysteretic adhesive contact of a 1-D bead chain, in C++.
//
// The native twin of the Python hook of mdgran/backends/lammps/backend.py (fix external pf/callback):
// same law, same step-quantized switching, same floating-point operations in the same order,
// so that the two agree to round-off ("events quantized", the default).  With "events located"
// the fix integrates the chain itself and locates each contact event inside the step, as
// mdgran's fast backend does: the pass steps the chain's activity front (the atoms not at rest
// and their neighbours; the others are a fixed point of the step, left untouched, bit for bit),
// and each event's window of beads is stepped again alone through its events while the beads
// next to it move on their parabolas, so the fix's part of a step costs O(front + events),
// and neither the front nor an event needs a collective call (LAMMPS's own part of a step,
// neighbour checks, communication, the force array, stays O(N)); second order in dt through
// snap events (sections "located events", "the activity front" and "event windows" below).  Units: mdgran's nondimensional ones through LAMMPS "lj"
// units (mdgran/model/units.py): bead mass 1, length p, force eta = pi R w,
// time 1/q, energy eta p.
//
//   fix ID all mdgran/chain keyword value ...
//     law schwarz|jkr|dmt|hertz   (schwarz)      fc value | lambda value  (lambda 0.64)
//     snap_off displacement|force (displacement) damping c   k1 k   k3 k   gap g   (all 0)
//     walls yes|no (no: tags 1 and N are fixed walls)   table FILE (default: exact law)
//     closed yes|no (initial state of every contact; yes unless gap > 0)
//     events quantized|located (quantized: with fix nve and fix spring/self; located: the fix
//            integrates the atoms of its group that are not walls and applies -k1 u itself,
//            so no fix nve and no fix spring/self may be defined beside it)
//     tether K   (quantized: the fix applies the linear substrate -K u to the moving atoms, the
//            force fix spring/self K x would add, bitwise, in its place; default 0: none)
//     integrate yes|no (quantized: the fix also moves the atoms of its group that are not walls
//            along x with fix nve's velocity Verlet, the same operations, in place of fix nve;
//            default no)
//     mixture FILE (unlike beads, mdgran.backends.lammps.plugin.write_mixture: by atom tag the bead's
//            1/m and substrate factor g, and for the contact to its right its scales A, 1/L,
//            L, threshold L delta_off and law class, each class with its fc and table: the
//            contact's force A f(delta / L), energy A L V(delta / L); a bead's acceleration
//            (F_left - F_right - g (k1 u + k3 u^3 + c_s w)) / m.  Quantized, LAMMPS's
//            integrator needs the same masses as per-atom masses (rmass); default: none)
//     sub_damping C (substrate damping: force -g C w on each bead, w the velocity estimate of
//            the contact damping; its power is added to D_viscous; default 0)
//     pulse TAG A T t0 (four values: a half-sine force A sin(pi (t - t0) / T) on the atom with
//            tag TAG for t0 <= t <= t0 + T; mdgran/model/drive.py; default: none)
//     base FILE (a base motion u_b(t) under the substrate, mdgran.backends.lammps.plugin.write_base:
//            its piecewise cubics on a uniform grid; the substrate then acts on u - u_b and
//            w - u_b', the walls stay at 0; default: none)
//   k1, k3, damping, sub_damping, tether, gap and lambda must be finite and >= 0: anything else
//   stops the input with one line naming the keyword.  The fix's restart block begins with a
//   mark and the count of its values; a block of another format, or written with (without) a
//   pulse or base motion this fix lacks (has), is refused.
//   With pulse or base the excitations are evaluated at the time of the forces (quantized:
//   t = step dt, the end of the position update; located: each pass's end), and their work
//   W, dW/dt = F v_b + u_b' sum_i F_sub,i, by the trapezoidal rule as D_viscous (quantized:
//   with the velocity estimate w, as the hook; located: with the velocities after the kick,
//   as the fast backend) is the vector's 4th element.
//
// Contacts by tag: contact k joins the atoms with tags k and k+1 (found with atom->map, so
// sorting and migration do not matter); compression delta_k = u_k - u_(k+1) - gap with
// u = x - x0 the displacement from the atom's initial x (walls: u = 0, v = 0).
//
// Law (docs/physics.md section 2; mdgran/model/contact.py), with t = sqrt(a) on the attached branch
// t >= t_min = sigma^(1/3), s = (fc + 2)/3, sigma = sqrt(s):
//     delta(t) = t^4 - 4 sigma t,   f(t) = fc + (t^3 - 3 sigma)^2        (Schwarz; JKR fc = -1.5,
//     V(delta) = P(t) - P(t0),      P' = f delta',  t0 = (4 sigma)^(1/3)  DMT fc = -2)
//     f = delta_+^(3/2),  V = (2/5) delta_+^(5/2)                          (Hertz)
// t(delta) by Newton on sqrt(delta - delta_min) (contact.py t_of_delta), or, with "table", the
// not-a-knot cubic spline in w = sqrt(delta - delta_min) written by mdgran.model.contact.ContactTable.
// fc from lambda: alpha = (1 - exp(-lambda/0.924))/1.02, fc = -6/(alpha^2 + 3).
//
// Per step, events quantized (post_force; hysteresis step-quantized as in the hook):
//   * a closed contact with delta <= delta_off opens (V(delta) goes to D_hysteresis), an open
//     one with delta >= 0 closes; strict inequalities where delta_off = 0 (DMT, Hertz).
//     delta_off = delta_min (snap_off displacement) or delta at f = fc (snap_off force).
//     Event time: linear interpolation of delta between the previous step and this one.
//   * force of a closed contact F = f(delta) + c d(delta)/dt (0 when open), pushing the right
//     atom by +F and the left one by -F; plus the cubic substrate -k3 u^3 on every atom.  The
//     linear substrate -k1 u is fix spring/self's, or with "tether K" this fix's -K u (one loop
//     fewer: fix spring/self costs ~5 ns per bead-step, a domain->unmap call per atom); k1 is
//     given here for the estimate below.
//   * post_force sees v(t + dt/2): the damping rate uses v(t + dt) ~ v(t + dt/2) + dt/2 a(t),
//     a(t) = contact + cubic + linear substrate force of the previous step (mass 1).
//   * a second call for the same step (the set-up of a "run") recomputes the force and
//     advances nothing.
//   * D_viscous: trapezoidal integral of the damping power c sum (d delta/dt)^2.
//
// Output: scalar = contact energy sum V (located: plus the substrate energy k1 u^2/2 + k3 u^4/4;
// fix_modify energy yes puts it into pe; a loop over every atom when asked, the atoms outside
// the activity front with their contacts' rest energy); vector =
// [D_hysteresis, D_viscous, number of events, external work, first and last tag of the moved
// hull (take_in_moved_state: outside it every atom is at x0 and at rest; quantized: 1, N),
// atoms stepped summed over the steps (located; quantized: 0), event windows joined with one
// already stepped (summed over the ranks that stepped them)]; array = events [time, contact number (1..n+1
// with walls, 2..n without), kind (1 close, 0 open), step]; per-atom vector = state of the
// contact to the atom's right (1 closed).  With several MPI ranks each contact is owned by
// the rank owning its left atom (events and dissipation there); the rank owning the right atom
// repeats the same update on a ghost copy of the state (forward-communicated every step with
// x0 and a(t)), so both agree; comm_modify vel yes and a ghost cut-off above the largest
// |x_(k+1) - x_k| of a closed contact are needed.  Located, every rank steps each event window
// that writes one of its atoms, from the step's start forwarded to the ghosts (x0, state, xs,
// vs, aprev), identically on every rank: it needs the atoms within WINDOW_MARGIN (3) beads of
// the window as ghosts, or the run stops with a line saying so (raise comm_modify cutoff);
// positions, velocities and events are then those of one rank bit for bit.  Sums over ranks
// are synced at set-up and at the end of every run, and when a global output is asked for
// (thermo, extract_fix).
#include "fix_mdgran_chain.h"
#include "law_constants.h"

#include "atom.h"
#include "comm.h"
#include "domain.h"
#include "error.h"
#include "force.h"
#include "memory.h"
#include "modify.h"
#include "output.h"
#include "update.h"
#include "utils.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>
#include <utility>

using namespace LAMMPS_NS;
using namespace FixConst;

// the law's numerical constants, one table with mdgran/model/contact_scalar.py (law_constants.h)
using mdgran_law::NEWTON_STEPS;
using mdgran_law::SING_BAND;
using mdgran_law::GL_X;
using mdgran_law::GL_W;
static constexpr int T_BLOCK = 16;        // compressions inverted together (t_of_delta_n)
static constexpr int NPERATOM = 4;        // stored in restart files: x0, closed, dprev, aprev
static constexpr double RESTART_MARK = 77007001.0;    // "mdgran chain", restart format 1
static constexpr int NEXCHANGE = 6;       // migrate with the atom: those, and xs, vs (located)
// located events (as mdgran/backends/fast_kernel.py)
static constexpr int MAX_SWITCHES = 4;    // switches of one contact at one instant (chatter)
static constexpr int MAX_SUBSTEPS = 10000;    // event splits of one window in one step
static constexpr int WINDOW_MARGIN = 3;   // a window needs the atoms within this many beads
                                          // of it: its neighbours, their other contacts, and
                                          // a flagged contact that would join it
static constexpr double SIMULTANEOUS = 1e-12;    // events within this * (1 + t) switch together
static constexpr double STATE_TOL = 1e-12;    // a contact beyond its switching point by more
                                              // than this (units p) switches at once
static constexpr double PI = 3.141592653589793;    // Python's math.pi (the pulse's sine)

FixMdgranChain::FixMdgranChain(LAMMPS *lmp, int narg, char **arg) :
    Fix(lmp, narg, arg), x0(nullptr), closed(nullptr), dprev(nullptr), aprev(nullptr),
    xs(nullptr), vs(nullptr), fcon(nullptr), u(nullptr), w(nullptr), left(nullptr),
    fkick(nullptr), nmax_scratch(0), contacts_stale(1), drift_h(-1.0)
{
  hertz = 0;
  fc = 0.0;
  double lambda = 0.64;
  int fc_given = 0, init_closed = -1;
  snap_force = 0;
  damping = k1 = k3 = gap = tether = 0.0;
  walls = 0;
  integrate = 0;
  use_table = 0;
  located = 0;
  mixed = extended = 0;
  sub_damping = 0.0;
  driven = pulse_tag = based = 0;
  pulse_amp = pulse_start = 0.0;
  pulse_dur = base_step = 1.0;
  now_ub = now_vb = now_fp = 0.0;
  work = work_all = work_prev = 0.0;
  std::string mixture_file, base_file;
  for (int iarg = 3; iarg < narg; iarg += 2) {
    if (iarg + 1 >= narg)
      error->all(FLERR, "fix mdgran/chain: keyword {} needs a value", arg[iarg]);
    std::string key = arg[iarg], val = arg[iarg + 1];
    if (key == "pulse") {    // four values: TAG A T t0
      if (iarg + 4 >= narg) error->all(FLERR, "fix mdgran/chain: pulse needs TAG A T t0");
      pulse_tag = (int) utils::inumeric(FLERR, val, false, lmp);
      pulse_amp = utils::numeric(FLERR, arg[iarg + 2], false, lmp);
      pulse_dur = utils::numeric(FLERR, arg[iarg + 3], false, lmp);
      pulse_start = utils::numeric(FLERR, arg[iarg + 4], false, lmp);
      if (pulse_tag < 1 || !(pulse_dur > 0.0))
        error->all(FLERR, "fix mdgran/chain: pulse needs TAG >= 1 and T > 0");
      iarg += 3;
    } else if (key == "base") base_file = val;
    else if (key == "law") {
      if (val == "hertz") hertz = 1;
      else if (val == "jkr") { fc = mdgran_law::FC_JKR; fc_given = 1; }
      else if (val == "dmt") { fc = mdgran_law::FC_DMT; fc_given = 1; }
      else if (val != "schwarz") error->all(FLERR, "fix mdgran/chain: unknown law {}", val);
    } else if (key == "fc") { fc = utils::numeric(FLERR, val, false, lmp); fc_given = 1; }
    else if (key == "lambda") lambda = utils::numeric(FLERR, val, false, lmp);
    else if (key == "snap_off") {
      if (val == "force") snap_force = 1;
      else if (val != "displacement") error->all(FLERR, "fix mdgran/chain: snap_off {}?", val);
    } else if (key == "damping") damping = utils::numeric(FLERR, val, false, lmp);
    else if (key == "k1") k1 = utils::numeric(FLERR, val, false, lmp);
    else if (key == "k3") k3 = utils::numeric(FLERR, val, false, lmp);
    else if (key == "tether") tether = utils::numeric(FLERR, val, false, lmp);
    else if (key == "integrate") integrate = utils::logical(FLERR, val, false, lmp);
    else if (key == "gap") gap = utils::numeric(FLERR, val, false, lmp);
    else if (key == "walls") walls = utils::logical(FLERR, val, false, lmp);
    else if (key == "closed") init_closed = utils::logical(FLERR, val, false, lmp);
    else if (key == "table") { use_table = 1; table_file = val; }
    else if (key == "mixture") mixture_file = val;
    else if (key == "sub_damping") sub_damping = utils::numeric(FLERR, val, false, lmp);
    else if (key == "events") {
      if (val == "located") located = 1;
      else if (val != "quantized")
        error->all(FLERR, "fix mdgran/chain: events must be located or quantized, not {}", val);
    }
    else error->all(FLERR, "fix mdgran/chain: unknown keyword {}", key);
  }
  const std::pair<const char *, double> nonnegative[] = {
      {"k1", k1}, {"k3", k3}, {"damping", damping}, {"sub_damping", sub_damping},
      {"tether", tether}, {"gap", gap}, {"lambda", lambda}};
  for (const auto &kv : nonnegative)
    if (!(kv.second >= 0.0 && std::isfinite(kv.second)))
      error->all(FLERR, "fix mdgran/chain: {} must be a finite number >= 0, not {}", kv.first,
                 kv.second);
  if (pulse_tag > 0 && !(std::isfinite(pulse_amp) && std::isfinite(pulse_start)))
    error->all(FLERR, "fix mdgran/chain: pulse A and t0 must be finite numbers");
  if (located && tether != 0.0)
    error->all(FLERR, "fix mdgran/chain: tether is for events quantized (located applies k1)");
  if (located && integrate)
    error->all(FLERR, "fix mdgran/chain: integrate is for events quantized (located integrates)");
  if (!hertz && !fc_given) {
    double alpha = (1.0 - std::exp(-lambda / mdgran_law::COS_LAMBDA)) / mdgran_law::COS_ALPHA;
    fc = -6.0 / (alpha * alpha + 3.0);
  }
  if (!hertz && !(fc >= mdgran_law::FC_DMT && fc <= mdgran_law::FC_JKR))
    error->all(FLERR, "fix mdgran/chain: fc must lie in [-2, -1.5], not {}", fc);

  set(hertz, fc, snap_force);
  if (use_table) {
    std::string msg = read_table(table_file.c_str());
    if (!msg.empty()) error->one(FLERR, msg);
  }
  if (init_closed < 0) init_closed = gap <= 0.0;

  if (atom->map_style == Atom::MAP_NONE)
    error->all(FLERR, "fix mdgran/chain needs an atom map (atom_modify map array)");
  if (domain->xperiodic) error->all(FLERR, "fix mdgran/chain: x must not be periodic");

  scalar_flag = 1;
  extscalar = 1;
  energy_global_flag = 1;
  vector_flag = 1;
  size_vector = 8;
  extvector = -1;    // the sums are extensive, the moved hull's tags are not
  array_flag = 1;
  size_array_rows = 0;
  ev_first = 0;
  size_array_cols = 4;
  size_array_rows_variable = 1;
  extarray = 0;
  global_freq = 1;
  peratom_flag = 1;
  size_peratom_cols = 0;
  peratom_freq = 1;
  restart_global = 1;
  restart_peratom = 1;
  comm_forward = located ? 5 : 3;
  maxexchange = NEXCHANGE;
  time_integrate = located || integrate;

  ntags = (tagint) atom->natoms;
  own_lo = known_lo = 1;
  own_hi = known_hi = ntags;
  wbase = 1;
  chat_time = -1.0;
  front_known = 0;    // the first step of a run steps every atom
  front_all = 1;
  front_lo = 1;
  front_hi = 0;
  hull_lo = ntags + 1;
  hull_hi = 0;
  moved_lo = ntags + 1;
  moved_hi = 0;
  moved_all[0] = 1.0;
  moved_all[1] = (double) ntags;
  bead_steps = bead_steps_all = 0.0;
  joins = joins_all = 0.0;
  if (!mixture_file.empty()) read_mixture(mixture_file.c_str());
  if (!base_file.empty()) read_base(base_file.c_str());
  driven = pulse_tag != 0 || based;
  if (pulse_tag > (int) ntags)
    error->all(FLERR, "fix mdgran/chain: pulse on tag {} of {} atoms", pulse_tag, ntags);
  extended = mixed || sub_damping != 0.0 || driven;
  grow_arrays(atom->nmax);
  atom->add_callback(Atom::GROW);
  atom->add_callback(Atom::RESTART);
  double **x = atom->x;
  for (int i = 0; i < atom->nlocal; i++) {
    x0[i] = x[i][0];
    closed[i] = (init_closed && atom->tag[i] < (tagint) atom->natoms) ? 1.0 : 0.0;
    dprev[i] = aprev[i] = 0.0;
    xs[i] = x[i][0];
    vs[i] = 0.0;
  }
  last_step = 0;
  have_last = 0;
  power_prev = d_hyst = d_visc = d_hyst_all = d_visc_all = 0.0;
  synced_step = -1;
  ncompute = 0;
  energy_at = -1;
  energy_cache = 0.0;
  ext_flags = {1, 1, 1, 1, 0, 0, 1, 1};    // last: an error above must not leave it to Fix to free
  extlist = ext_flags.data();        // ours (the destructor sets it back to null)
}

FixMdgranChain::~FixMdgranChain()
{
  extlist = nullptr;    // ext_flags owns it
  if (copymode) return;
  atom->delete_callback(id, Atom::GROW);
  atom->delete_callback(id, Atom::RESTART);
  memory->destroy(x0);
  memory->destroy(closed);
  memory->destroy(dprev);
  memory->destroy(aprev);
  memory->destroy(xs);
  memory->destroy(vs);
  memory->destroy(fkick);
  memory->destroy(fcon);
  memory->destroy(u);
  memory->destroy(w);
  memory->destroy(left);
}

int FixMdgranChain::setmask()
{
  int mask = PRE_NEIGHBOR | POST_FORCE;
  if (located || integrate) mask |= INITIAL_INTEGRATE;
  if (integrate) mask |= FINAL_INTEGRATE;
  return mask;
}

void FixMdgranChain::init()
{
  if (comm->nprocs > 1 && !comm->ghost_velocity)
    error->all(FLERR, "fix mdgran/chain on several ranks needs comm_modify vel yes");
  if (atom->natoms > MAXSMALLINT) error->all(FLERR, "fix mdgran/chain: too many atoms");
  if (tether != 0.0)
    for (auto *fix : modify->get_fix_list())
      if (utils::strmatch(fix->style, "^spring/self"))
        error->all(FLERR, "fix mdgran/chain tether applies the linear substrate itself: unfix "
                   "{} (fix spring/self)", fix->id);
  if (!located && !integrate) return;
  // located: this fix moves the chain and owns every x force, so no other fix may do either;
  // integrate yes: it moves the chain
  for (auto *fix : modify->get_fix_list()) {
    if (fix == this) continue;
    if (fix->time_integrate)
      error->all(FLERR, "fix mdgran/chain {} integrates the chain itself: unfix {} (fix {})",
                 located ? "events located" : "integrate yes", fix->id, fix->style);
    if (located && utils::strmatch(fix->style, "^spring/self"))
      error->all(FLERR, "fix mdgran/chain events located applies the linear substrate k1 "
                 "itself: unfix {} (fix spring/self)", fix->id);
  }
}

// ---- the law ------------------------------------------------------------------------------

// The law's constants, evaluated as mdgran/model/contact.py does (same libm calls).
void MdgranLaw::set(int hertz_law, double fc_law, int snap_force)
{
  hertz = hertz_law;
  fc = fc_law;
  double s = hertz ? 0.0 : (fc + 2.0) / 3.0;
  sigma = std::sqrt(std::max(s, 0.0));
  tm = std::pow(sigma, 1.0 / 3.0);
  big = 6.0 * tm * tm;
  sqrt_big = std::sqrt(big);
  delta_min = hertz ? 0.0 : std::pow(tm, 4.0) - 4.0 * sigma * tm;
  double tf = std::pow(3.0 * sigma, 1.0 / 3.0);
  double delta_fmax = std::pow(tf, 4.0) - 4.0 * sigma * tf;
  delta_off = hertz ? 0.0 : (snap_force ? delta_fmax : delta_min);
  strict = delta_off == 0.0;
  t0 = std::pow(4.0 * sigma, 1.0 / 3.0);
  p_t0 = hertz ? 0.0 : antiderivative(t0);    // V's constant, once (3 pow calls per energy)
  // displacement snap-off of Schwarz: f ~ sqrt(delta - delta_min) near the event
  sing = (!hertz && !snap_force && tm > 0.0) ? delta_min + SING_BAND : -INFINITY;
}

// Branch parameter t >= t_min with t^4 - 4 sigma t = delta: Newton on
// phi(w) = w sqrt(w^2 + 4 tm w + 6 tm^2) = sqrt(delta - delta_min), w = t - tm, from above.
double MdgranLaw::t_of_delta(double d) const
{
  double t;
  t_of_delta_n(&d, &t, 1);
  return t;
}

// t_of_delta of n <= T_BLOCK compressions at once, each with the same operations: the Newton
// steps of the n values interleave (one value's steps are a chain of dependent square roots
// and divisions; the contact energy of 1e5 contacts took 17 ms one by one)
void MdgranLaw::t_of_delta_n(const double *d, double *t, int n) const
{
  double rhs[T_BLOCK], w[T_BLOCK];
  for (int j = 0; j < n; j++) rhs[j] = std::sqrt(std::max(d[j] - delta_min, 0.0));
  if (tm == 0.0) {    // DMT: phi(w) = w^2
    for (int j = 0; j < n; j++) t[j] = std::sqrt(rhs[j]);
    return;
  }
  for (int j = 0; j < n; j++) w[j] = std::min(rhs[j] / sqrt_big, std::sqrt(rhs[j]));
  for (int it = 0; it < NEWTON_STEPS; it++)
    for (int j = 0; j < n; j++) {
      double sq = std::sqrt(w[j] * w[j] + 4.0 * tm * w[j] + big);
      w[j] = w[j] - (w[j] * sq - rhs[j]) / (sq + w[j] * (w[j] + 2.0 * tm) / sq);
    }
  for (int j = 0; j < n; j++) t[j] = tm + std::max(w[j], 0.0);
}

double MdgranLaw::exact_force(double d) const
{
  if (hertz) {
    double dp = std::max(d, 0.0);
    return dp * std::sqrt(dp);
  }
  double u = std::pow(t_of_delta(d), 3.0) - 3.0 * sigma;
  return fc + u * u;
}

double MdgranLaw::law_force(double d) const
{
  return use_table ? spline_force(d) : exact_force(d);
}

// antiderivative of f(t) delta'(t): V(delta) = P(t(delta)) - P(t0)
double MdgranLaw::antiderivative(double t) const
{
  const double sg = sigma;
  return 0.4 * std::pow(t, 10.0) - 4.0 * sg * std::pow(t, 7.0) +
      (fc + 15.0 * sg * sg) * std::pow(t, 4.0) - 4.0 * sg * (fc + 9.0 * sg * sg) * t;
}

double MdgranLaw::law_energy(double d) const
{
  if (hertz) {
    double dp = std::max(d, 0.0);
    return 0.4 * dp * dp * std::sqrt(dp);
  }
  return antiderivative(t_of_delta(d)) - p_t0;
}

// The spline table of mdgran.model.contact.ContactTable.write_spline: keyword lines, then the
// (n - 1) x 4 coefficients of the force, every number with 17 digits (exact round trip).
std::string MdgranLaw::read_table(const char *file)
{
  std::ifstream in(file);
  if (!in) return "fix mdgran/chain: cannot open table " + std::string(file);
  std::string line, key;
  tab_n = 0;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream ls(line);
    ls >> key;
    if (key == "MDGRAN_SPLINE_W") continue;
    if (key == "coefficients") break;
    std::string val;
    ls >> val;
    double v = std::strtod(val.c_str(), nullptr);
    if (key == "n") tab_n = (int) v;
    else if (key == "base") tab_base = v;
    else if (key == "scale") tab_scale = v;
    else if (key == "h") tab_h = v;
    else if (key == "delta_max") tab_delta_max = v;
  }
  if (tab_n < 2) return "fix mdgran/chain: table " + std::string(file) + " has no 'n' line";
  tab_coef.resize(4 * (size_t) (tab_n - 1));
  std::string tok;
  for (size_t k = 0; k < tab_coef.size(); k++) {
    if (!(in >> tok)) return "fix mdgran/chain: table " + std::string(file) + " is truncated";
    tab_coef[k] = std::strtod(tok.c_str(), nullptr);
  }
  use_table = 1;
  return "";
}

// The unlike beads of "mixture FILE" (written by mdgran/backends/lammps/backend.py): keyword lines
//   MDGRAN_MIXTURE,  ntags N,  classes C,  class K fc VALUE [table FILE]  (C of them),  tags
// then N lines "tag 1/m g A 1/L L delta_off class" (numbers with 17 digits: exact round trip).
// Every class has the chain's kind (hertz or not) and snap-off rule, and its own fc and table.
void FixMdgranChain::read_mixture(const char *file)
{
  std::ifstream in(file);
  if (!in) error->one(FLERR, "fix mdgran/chain: cannot open mixture {}", file);
  std::string line, key;
  long n = -1;
  int nclass = 0;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream ls(line);
    ls >> key;
    if (key == "tags") break;
    if (key == "ntags") ls >> n;
    else if (key == "classes") {
      ls >> nclass;
      laws.resize(std::max(nclass, 0));
    } else if (key == "class") {
      int k = -1;
      std::string fckey, fcval, tkey, tfile;
      ls >> k >> fckey >> fcval;
      if (k < 0 || k >= nclass || fckey != "fc")
        error->one(FLERR, "fix mdgran/chain: mixture {}: bad line '{}'", file, line);
      laws[k].set(hertz, std::strtod(fcval.c_str(), nullptr), snap_force);
      if (ls >> tkey >> tfile) {
        std::string msg = laws[k].read_table(tfile.c_str());
        if (!msg.empty()) error->one(FLERR, msg);
      }
    }
  }
  if (n != (long) ntags)
    error->one(FLERR, "fix mdgran/chain: mixture {} is for {} atoms, not {}", file, n, ntags);
  for (auto *v : {&m_inv_mass, &m_on_site, &m_scale, &m_inv_len, &m_length, &m_delta_off})
    v->assign(n + 1, 0.0);
  m_cls.assign(n + 1, 0);
  std::string tok[8];
  for (long k = 0; k < n; k++) {
    for (auto &t : tok)
      if (!(in >> t)) error->one(FLERR, "fix mdgran/chain: mixture {} is truncated", file);
    long t = std::strtol(tok[0].c_str(), nullptr, 10);
    int cls = (int) std::strtol(tok[7].c_str(), nullptr, 10);
    if (t < 1 || t > n || cls < 0 || cls >= nclass)
      error->one(FLERR, "fix mdgran/chain: mixture {}: bad row of tag {}", file, tok[0]);
    m_inv_mass[t] = std::strtod(tok[1].c_str(), nullptr);
    m_on_site[t] = std::strtod(tok[2].c_str(), nullptr);
    m_scale[t] = std::strtod(tok[3].c_str(), nullptr);
    m_inv_len[t] = std::strtod(tok[4].c_str(), nullptr);
    m_length[t] = std::strtod(tok[5].c_str(), nullptr);
    m_delta_off[t] = std::strtod(tok[6].c_str(), nullptr);
    m_cls[t] = cls;
  }
  mixed = 1;
}

// The base motion of mdgran.backends.lammps.plugin.write_base: "MDGRAN_BASE", "step h", "rows n", then
// n rows of 4 coefficients (highest power first), numbers as repr (exact)
void FixMdgranChain::read_base(const char *file)
{
  std::ifstream in(file);
  if (!in) error->one(FLERR, "fix mdgran/chain: cannot open base {}", file);
  std::string key, tok;
  long n = -1;
  int magic = 0;
  while (in >> key) {
    if (key == "MDGRAN_BASE") magic = 1;
    else if (key == "step" && in >> tok) base_step = std::strtod(tok.c_str(), nullptr);
    else if (key == "rows" && in >> n) break;
  }
  if (!magic || n < 1 || !(base_step > 0.0))
    error->one(FLERR, "fix mdgran/chain: {} is not a base motion file", file);
  base_coef.assign(4 * n, 0.0);
  for (long k = 0; k < 4 * n; k++) {
    if (!(in >> tok)) error->one(FLERR, "fix mdgran/chain: base {} is truncated", file);
    base_coef[k] = std::strtod(tok.c_str(), nullptr);
  }
  based = 1;
}

// u_b, u_b' and the pulse's force at time t: the operations of the hook's drive_at (and the
// fast kernel's)
void FixMdgranChain::drive_at(double t, double &ub, double &vb, double &fp) const
{
  ub = vb = fp = 0.0;
  if (pulse_tag != 0) {
    double s = (t - pulse_start) / pulse_dur;
    if (0.0 <= s && s <= 1.0) fp = pulse_amp * std::sin(PI * s);
  }
  if (based) {
    const long rows = (long) (base_coef.size() / 4);
    const long k = std::min((long) std::floor(std::max(t, 0.0) / base_step), rows - 1);
    const double y = t - (double) k * base_step;
    const double *c = &base_coef[4 * k];
    ub = ((c[0] * y + c[1]) * y + c[2]) * y + c[3];
    vb = (3.0 * c[0] * y + 2.0 * c[1]) * y + c[2];
  }
}

// located: rate of the excitations' work over this rank's moving atoms at the current state and
// the time of set_drive_time, with the actual velocities: F v_b + u_b' sum_i F_sub,i
double FixMdgranChain::external_power() const
{
  const double *x = flat(atom->x), *v = flat(atom->v);
  const tagint *tag = atom->tag;
  double p = 0.0, total = 0.0;
  const std::vector<int> &runs_ = active_runs();    // the front's: the pulse's atom is in it,
  for (size_t r = 0; r < runs_.size(); r += 2)     // and with a base every atom is
    for (int i = runs_[r]; i < runs_[r + 1]; i++) {
      if (tag[i] == pulse_tag) p += now_fp * v[3 * i];
      if (based) {
        const double y = x[3 * i] - x0[i] - now_ub;
        double fs = -(k1 * y + k3 * y * y * y + sub_damping * (v[3 * i] - now_vb));
        total += mixed ? m_on_site[tag[i]] * fs : fs;
      }
    }
  return p + now_vb * total;
}

// Force of the closed unlike contact whose left atom has tag jt, at compression d:
// F = A f(d / L) with f its class's law (located_law: as located_force, else law_force)
inline double FixMdgranChain::mixed_force(tagint jt, double d, int located_law) const
{
  const MdgranLaw &law = laws[m_cls[jt]];
  double u = d * m_inv_len[jt];
  return m_scale[jt] * (located_law ? law.located_force(u) : law.law_force(u));
}

// Energy of that contact, A L V(d / L) (exact law)
double FixMdgranChain::mixed_energy(tagint jt, double d) const
{
  return m_scale[jt] * m_length[jt] * laws[m_cls[jt]].law_energy(d * m_inv_len[jt]);
}

// ---- the step -----------------------------------------------------------------------------

inline double FixMdgranChain::disp(int i) const
{
  return is_wall(atom->tag[i]) ? 0.0 : atom->x[i][0] - x0[i];
}

// The contact list holds local indices: it is rebuilt after LAMMPS re-neighbours (atoms
// migrate and the ghosts are made anew, so local indices change), at the set-up of a run, and
// never in between (it cost ~17% of a step when rebuilt every step).
void FixMdgranChain::setup_pre_neighbor()
{
  pre_neighbor();
}

void FixMdgranChain::pre_neighbor()
{
  contacts_stale = 1;
  drift_h = -1.0;    // local indices change: u and w of the drift are void
  if (!located) return;
  share_ranges();    // the ghosts are new: which atoms each rank holds
  front_take_arrivals();
}

void FixMdgranChain::setup(int vflag)
{
  contacts_stale = 1;
  if (located) located_setup();
  else post_force(vflag);
  sync();
}

void FixMdgranChain::post_force(int /*vflag*/)
{
  if (located) located_step();
  else compute(update->ntimestep);
}

// The step of events quantized: the chain's one law (MIX false, the code every homogeneous
// run takes), or each contact's own (MIX: unlike beads), chosen once per call.
void FixMdgranChain::compute(bigint step)
{
  if (mixed) compute_t<true>(step);
  else compute_t<false>(step);
}

template <bool MIX> void FixMdgranChain::compute_t(bigint step)
{
  const int new_step = !have_last || step != last_step;
  ncompute++;
  comm->forward_comm(this);    // ghosts get x0, state and a(t) of their owners
  const int nlocal = atom->nlocal, nall = nlocal + atom->nghost;
  if (nall > nmax_scratch) ensure_scratch();
  tagint *tag = atom->tag;
  double **x = atom->x, **v = atom->v;
  const tagint natoms = ntags = (tagint) atom->natoms;
  const double dt = update->dt;
  const double t = (double) step * dt;
  const int use_est = step > 0 && have_last;
  const int nprocs = comm->nprocs;
  double power = 0.0;
  std::vector<Event> found;    // events of this step with their lost energy
  std::vector<double> lost;

  // 0. displacement u = x - x0 and velocity estimate w of every atom, owned and ghost (walls:
  // 0); members as locals (name_), as in located_pass
  if (contacts_stale) build_contacts();
  double *const u_ = u, *const w_ = w, *const fcon_ = fcon, *const closed_ = closed;
  double *const dprev_ = dprev, *const aprev_ = aprev;
  const double *const x0_ = x0, *const xf = flat(x), *const vf = flat(v);
  const double gap_ = gap, damping_ = damping, delta_off_ = delta_off, hdt = 0.5 * dt;
  if (use_est)    // owned atoms: left by integrate yes's first half (nve), if it ran
    for (int i = drift_h == dt ? nlocal : 0; i < nall; i++) {
      u_[i] = xf[3 * i] - x0_[i];
      w_[i] = vf[3 * i] + hdt * aprev_[i];
    }
  else
    for (int i = 0; i < nall; i++) {
      u_[i] = xf[3 * i] - x0_[i];
      w_[i] = vf[3 * i];
    }
  for (int i : wall_atoms) u_[i] = w_[i] = 0.0;
  drift_h = -1.0;

  // a switch of contact l at this step (rare): its event time and lost energy, on the owner
  auto record = [&](int l, double delta, int opening) __attribute__((noinline)) {
    double prev = have_last ? dprev[l] : delta;
    double thr = opening ? (MIX ? m_delta_off[tag[l]] : delta_off) : 0.0;
    double span = prev - delta;
    double frac = span != 0.0 ? (prev - thr) / span : 1.0;
    double te = step > 0 ? t - dt + std::min(std::max(frac, 0.0), 1.0) * dt : t;
    found.push_back({step, tag[l], opening ? 0 : 1, te});
    double e = 0.0;
    if (opening) e = MIX ? mixed_energy(tag[l], delta) : law_energy(delta);
    lost.push_back(e);
  };
  auto overflow = [&](int l, double delta) __attribute__((noinline)) {
    error->one(FLERR,
               "compression {:.4g} beyond the contact table (delta_max = {:g}) at t = {:.12g}, "
               "contact {}", delta, tab_delta_max, t, contact_number(tag[l]));
  };
  // one contact (left atom l, right atom r): state update at a new step, then its force
  auto contact = [&](int l, int r, int own) __attribute__((always_inline)) {
    double delta = u_[l] - u_[r];
    if (gap_ != 0.0) delta = delta - gap_;
    double rate = w_[l] - w_[r];
    double off = delta_off_;
    int strict_ = strict;
    if constexpr (MIX) {    // unlike beads: the contact's own threshold and table range
      const tagint jt = tag[l];
      off = m_delta_off[jt];
      strict_ = off == 0.0;
      const MdgranLaw &law = laws[m_cls[jt]];
      if (law.use_table && delta * m_inv_len[jt] > law.tab_delta_max)
        overflow(l, delta * m_inv_len[jt]);
    }
    if (new_step) {
      int c = closed_[l] != 0.0;
      int opening = c && (strict_ ? delta < 0.0 : delta <= off);
      int closing = !c && (strict_ ? delta > 0.0 : delta >= 0.0);
      if (opening || closing) {
        if (own) record(l, delta, opening);
        closed_[l] = opening ? 0.0 : 1.0;
      }
      if (own) dprev_[l] = delta;
    }
    if (!MIX && use_table && delta > tab_delta_max) overflow(l, delta);
    double F = 0.0;
    if (closed_[l] != 0.0) {
      if constexpr (MIX) F = mixed_force(tag[l], delta, 0);
      else F = use_table ? spline_force(delta) : exact_force(delta);
      if (damping_ != 0.0) F = F + damping_ * rate;
      if (own && new_step && damping_ != 0.0) power += rate * rate;
    }
    fcon_[l] = F;
  };

  // 1. the contacts this rank evaluates (build_contacts): owned left atom (own), or a ghost
  // left atom and an owned right one (the same update on the copy)
  const Con *const con = cons.data();
  const int ncon = (int) cons.size();
  for (int k = 0; k < ncon; k++) contact(con[k].l, con[k].r, con[k].own);
  // 3. forces on owned atoms: x'' = F_left - F_right - k3 u^3 (- k1 u by fix spring/self, or
  // by this fix with tether: 0 + (ext - K u), the number fix spring/self's (0 + ext) - K u is)
  double *const f = flat(atom->f);
  const int *const mask = atom->mask, *const left_ = left;
  const double k1_ = k1, k3_ = k3, tether_ = tether;
  const int bit = groupbit;
  double check = 0.0, sub_power = 0.0, ext_power = 0.0;
  if (driven) {    // the hook's _bead_forces_driven: the substrate on y = u - u_b, w - u_b', the
    // pulse on its atom, at t = step dt; the excitations' power F w_b + u_b' sum_i F_sub,i
    double ub, vb, fp, sub_sum = 0.0;
    drive_at(t, ub, vb, fp);
    for (int i = 0; i < nlocal; i++) {
      double ext = 0.0, g = 0.0, y = 0.0;
      if (!is_wall(tag[i])) {
        g = mixed ? m_on_site[tag[i]] : 1.0;
        y = u_[i] - ub;
        const double wv = w_[i] - vb;
        double fl = left_[i] >= 0 ? fcon_[left_[i]] : 0.0;
        ext = (0.0 - fcon_[i]) + fl;
        double fsub = 0.0;
        if (k3_ != 0.0) {
          const double c3 = g * (k3_ * std::pow(y, 3.0));
          ext = ext - c3;
          fsub = fsub - c3;
        }
        if (sub_damping != 0.0) {
          const double cd = g * (sub_damping * wv);
          ext = ext - cd;
          fsub = fsub - cd;
          if (new_step) sub_power += g * (sub_damping * wv * wv);
        }
        if (tag[i] == pulse_tag) {
          ext = ext + fp;
          if (new_step) ext_power += fp * w_[i];
        }
        if (based && new_step) sub_sum += fsub - g * (k1_ * y);
      }
      check += ext * 0.0;
      if (mask[i] & bit) f[3 * i] += tether_ != 0.0 ? ext - g * (tether_ * y) : ext;
      if (new_step) {
        double a = k1_ != 0.0 ? ext - g * (k1_ * y) : ext;
        aprev_[i] = mixed ? a * m_inv_mass[tag[i]] : a;
      }
    }
    ext_power = ext_power + vb * sub_sum;
  } else if (!extended)
    for (int i = 0; i < nlocal; i++) {
      double ext = 0.0;
      const int wall = is_wall(tag[i]);
      if (!wall) {
        double fl = left_[i] >= 0 ? fcon_[left_[i]] : 0.0;
        ext = (0.0 - fcon_[i]) + fl;
        if (k3_ != 0.0) ext = ext - k3_ * std::pow(u_[i], 3.0);
      }
      check += ext * 0.0;    // 0, unless some ext is not finite (NaN then)
      if (mask[i] & bit) f[3 * i] += tether_ != 0.0 && !wall ? ext - tether_ * u_[i] : ext;
      if (new_step) aprev_[i] = k1_ != 0.0 ? ext - k1_ * u_[i] : ext;
    }
  else    // unlike beads or substrate damping (the hook's _bead_forces_mixed): bead of mass m,
    // substrate factor g: F_left - F_right - g (k3 u^3 + c_s w + K u); a(t) = (.. k1 ..) / m
    for (int i = 0; i < nlocal; i++) {
      double ext = 0.0, g = 0.0;
      if (!is_wall(tag[i])) {
        g = mixed ? m_on_site[tag[i]] : 1.0;
        double fl = left_[i] >= 0 ? fcon_[left_[i]] : 0.0;
        ext = (0.0 - fcon_[i]) + fl;
        if (k3_ != 0.0) ext = ext - g * (k3_ * std::pow(u_[i], 3.0));
        if (sub_damping != 0.0) {
          ext = ext - g * (sub_damping * w_[i]);
          if (new_step) sub_power += g * (sub_damping * w_[i] * w_[i]);
        }
      }
      check += ext * 0.0;
      if (mask[i] & bit) f[3 * i] += tether_ != 0.0 ? ext - g * (tether_ * u_[i]) : ext;
      if (new_step) {
        double a = k1_ != 0.0 ? ext - g * (k1_ * u_[i]) : ext;
        aprev_[i] = mixed ? a * m_inv_mass[tag[i]] : a;
      }
    }
  if (check != 0.0) {    // rare: find the first bead with a non-finite force
    for (int i = 0; i < nlocal; i++) {
      double fl = left[i] >= 0 ? fcon[left[i]] : 0.0;
      if (!is_wall(tag[i]) && !std::isfinite(fl - fcon[i] - (k3 != 0.0 ? k3 * u[i] : 0.0)))
        error->one(FLERR, "non-finite force at t = {:.12g}, bead {}", t,
                   walls ? tag[i] - 1 : tag[i]);
    }
    error->one(FLERR, "non-finite force at t = {:.12g}", t);
  }

  if (!new_step) return;
  // events in contact order (as the hook), D_hysteresis summed in that order
  std::vector<size_t> order(found.size());
  for (size_t e = 0; e < order.size(); e++) order[e] = e;
  std::sort(order.begin(), order.end(),
            [&](size_t a, size_t b) { return found[a].left < found[b].left; });
  for (size_t e : order) {
    if (nprocs == 1) {
      d_hyst_all += lost[e];
      ev_all.push_back(found[e]);
    } else {
      d_hyst += lost[e];
      ev_local.push_back(found[e]);
    }
  }
  power = damping != 0.0 ? damping * power : 0.0;
  if (sub_damping != 0.0) power = power + sub_power;
  if (have_last) {
    double dv = 0.5 * (power + power_prev) * dt;
    if (nprocs == 1) d_visc_all += dv;
    else d_visc += dv;
    if (driven) {
      double dw = 0.5 * (ext_power + work_prev) * dt;
      if (nprocs == 1) work_all += dw;
      else work += dw;
    }
  }
  power_prev = power;
  work_prev = ext_power;
  last_step = step;
  have_last = 1;
  size_array_rows = event_rows();
}

// sums over ranks and the event list gathered on every rank (collective)
void FixMdgranChain::sync()
{
  if (comm->nprocs == 1) return;
  synced_step = update->ntimestep;
  double hull[2] = {(double) moved_lo, -(double) moved_hi}, both[2];
  MPI_Allreduce(hull, both, 2, MPI_DOUBLE, MPI_MIN, world);
  moved_all[0] = both[0];
  moved_all[1] = -both[1];
  double tallies[2] = {bead_steps, joins}, tallies_all[2];
  MPI_Allreduce(tallies, tallies_all, 2, MPI_DOUBLE, MPI_SUM, world);
  bead_steps_all = tallies_all[0];
  joins_all = tallies_all[1];
  double part[3] = {d_hyst, d_visc, work}, sum[3];
  MPI_Allreduce(part, sum, 3, MPI_DOUBLE, MPI_SUM, world);
  d_hyst_all += sum[0];
  d_visc_all += sum[1];
  work_all += sum[2];
  d_hyst = d_visc = work = 0.0;
  int nmine = (int) ev_local.size() * 4, nproc = comm->nprocs;
  std::vector<int> counts(nproc), displs(nproc);
  MPI_Allgather(&nmine, 1, MPI_INT, counts.data(), 1, MPI_INT, world);
  int ntot = 0;
  for (int p = 0; p < nproc; p++) {
    displs[p] = ntot;
    ntot += counts[p];
  }
  std::vector<double> mine(nmine + 1), all(ntot + 1);
  for (size_t e = 0; e < ev_local.size(); e++) {
    mine[4 * e] = (double) ev_local[e].step;
    mine[4 * e + 1] = (double) ev_local[e].left;
    mine[4 * e + 2] = ev_local[e].kind;
    mine[4 * e + 3] = ev_local[e].time;
  }
  MPI_Allgatherv(mine.data(), nmine, MPI_DOUBLE, all.data(), counts.data(), displs.data(),
                 MPI_DOUBLE, world);
  std::vector<Event> got(ntot / 4);
  for (size_t e = 0; e < got.size(); e++)
    got[e] = {(bigint) all[4 * e], (tagint) all[4 * e + 1], (int) all[4 * e + 2], all[4 * e + 3]};
  if (located)    // in time order (simultaneous ones by contact)
    std::sort(got.begin(), got.end(), [](const Event &a, const Event &b) {
      return a.time != b.time ? a.time < b.time : a.left < b.left;
    });
  else    // per step by contact, as the hook
    std::sort(got.begin(), got.end(), [](const Event &a, const Event &b) {
      return a.step != b.step ? a.step < b.step : a.left < b.left;
    });
  ev_all.insert(ev_all.end(), got.begin(), got.end());
  ev_local.clear();
  size_array_rows = event_rows();
}

void FixMdgranChain::post_run()
{
  sync();
}

inline double FixMdgranChain::ustart(int i) const
{
  return is_wall(atom->tag[i]) ? 0.0 : xs[i] - x0[i];
}
inline double FixMdgranChain::vstart(int i) const
{
  return is_wall(atom->tag[i]) ? 0.0 : vs[i];
}
inline double FixMdgranChain::astart(int i) const
{
  return is_wall(atom->tag[i]) ? 0.0 : aprev[i];
}
inline int FixMdgranChain::moves(int i) const
{
  return (atom->mask[i] & groupbit) && !is_wall(atom->tag[i]);
}

// scratch arrays (owned and ghost atoms), grown with atom->nmax
void FixMdgranChain::ensure_scratch()
{
  nmax_scratch = atom->nmax;
  contacts_stale = 1;    // left[] and the zeroed forces are gone
  drift_h = -1.0;        // and u, w
  memory->destroy(fcon);
  memory->destroy(u);
  memory->destroy(w);
  memory->destroy(left);
  memory->destroy(fkick);
  memory->create(fcon, nmax_scratch, "mdgran/chain:fcon");
  memory->create(u, nmax_scratch, "mdgran/chain:u");
  memory->create(w, nmax_scratch, "mdgran/chain:w");
  memory->create(left, nmax_scratch, "mdgran/chain:left");
  memory->create(fkick, nmax_scratch, "mdgran/chain:fkick");
}

// ---- located events ------------------------------------------------------------------------
//
// With "events located" the fix replaces fix nve and fix spring/self: it integrates the chain
// with the velocity Verlet of mdgran's fast backend (mdgran/backends/fast_kernel.py), locating
// every contact event inside the step.  A step (or a window's sub-step) of length h from
// (x0, v0, a0):
//     v_half = v0 + h/2 a0,   x1 = x0 + h v_half            (drift; initial_integrate)
//     v_est  = v_half + h/2 a0                               (damping rate at the end)
//     a1     = a(x1, v_est),  v1 = v_half + h/2 a1           (kick; post_force)
//     D_visc += h/2 (P0 + P1),   P = c sum_closed (d delta/dt)^2
// with a = F_left - F_right - k1 u - k3 u^3 (contact forces of the two neighbours, substrate).
// Near snap-off (Schwarz, displacement rule: f ~ sqrt(delta - delta_min)) the kick uses the
// mean force over the step, Fv = 2 (V(d1) - V(d0)) / (d1 - d0) - f(d0), so that
// h/2 (f(d0) + Fv) = h f_mean: second order through the singular force.
//
// Inside a step every atom moves on the parabola x0 + s v0 + s^2/2 a0, so the event function
// of each contact, g = delta - delta_off (closed) or -delta (open), positive inside the state,
// is the quadratic g(s) = g0 + s g0' + s^2/2 g0''.  The pass steps the whole chain over dt and
// flags a contact when its end value could hide a crossing (g1 < 0 or g1 < h/2 g'(h)).  A
// contact that switches at s inside the step changes the force on its two beads only, so the
// event is handled there: the beads of the flagged contacts with a root in the step form event
// windows, each stepped again alone from the step's start and split at its own events (section
// "event windows" below: the contacts with a root within SIMULTANEOUS of the window's earliest
// switch there, opening: D_hysteresis += V(delta(te)), exact law; contacts on their switching
// point and moving out switch back at once, settle), while the beads next to it move on their
// parabolas.  A step costs one drift, one force pass and one kick over the activity front
// (section "the activity front"), plus a few passes over a few beads per event; no event needs
// a collective call.

// The contacts this rank evaluates: those of its owned atoms with their right neighbour (own),
// and those whose left atom is a ghost and right atom owned (a copy updated identically).
// left[i] of an owned atom: local index of its left neighbour, -1 if none is evaluated here.
void FixMdgranChain::build_contacts()
{
  const int nlocal = atom->nlocal;
  const int nall = nlocal + atom->nghost;
  if (nall > nmax_scratch) ensure_scratch();
  tagint *tag = atom->tag;
  const tagint natoms = ntags = (tagint) atom->natoms;
  contacts_stale = 0;
  cons.clear();
  // forces of atoms without a contact on their right stay 0; the others are set every pass
  for (int i = 0; i < nall; i++) fcon[i] = fkick[i] = 0.0;
  for (int i = 0; i < nlocal; i++) left[i] = -1;
  for (int i = 0; i < nlocal; i++) {
    if (tag[i] >= natoms) continue;
    int j = atom->map(tag[i] + 1);
    if (j < 0) {
      if (closed[i] != 0.0)
        error->one(FLERR, "fix mdgran/chain: contact {} is closed but atom {} is beyond the "
                   "ghost cut-off (raise comm_modify cutoff)", contact_number(tag[i]), tag[i] + 1);
      continue;
    }
    if (j < nlocal) left[j] = i;
    cons.push_back({i, j, 1});
  }
  for (int i = 0; i < nlocal; i++) {
    if (left[i] >= 0 || tag[i] <= 1) continue;
    int l = atom->map(tag[i] - 1);
    left[i] = l;
    if (l >= nlocal) cons.push_back({l, i, 0});
  }
  con_of.assign(nall, -1);    // the activity front's contacts by left atom
  for (size_t k = 0; k < cons.size(); k++) con_of[cons[k].l] = (int) k;
  gcons.clear();    // located, several ranks: the ghosts' own contacts, for event windows
  if (located)
    for (int i = nlocal; i < nall; i++) {
      if (tag[i] >= natoms) continue;
      int j = atom->map(tag[i] + 1);
      if (j >= nlocal) gcons.push_back({i, j, 0});
    }
  // the owned atoms this fix moves (located, or integrate yes), as runs [begin, end) of local
  // indices (the loops over them then test nothing per atom), the others (still), and the
  // walls among the owned and ghost atoms (u = 0, v = 0)
  runs.clear();
  still.clear();
  wall_atoms.clear();
  for (int i = 0; i < nlocal; i++) {
    if (!moves(i)) still.push_back(i);
    else if (!runs.empty() && runs.back() == i) runs.back() = i + 1;
    else runs.insert(runs.end(), {i, i + 1});
  }
  for (int i = 0; i < nall; i++)
    if (is_wall(tag[i])) wall_atoms.push_back(i);
}

// Mean force over the compression interval, (V(d1) - V(d0)) / (d1 - d0) (Schwarz): in the
// branch parameter t the mean of f(t) weighted by delta'(t) = 4 (t^3 - sigma) over [t0, t1];
// f delta' is a polynomial of degree 9, so 5-point Gauss-Legendre is exact.
double MdgranLaw::mean_force(double d0, double d1) const
{
  return mean_force_t(t_of_delta(d0), t_of_delta(d1));
}

// mean_force from the branch parameters ta = t(d0), tb = t(d1) of the interval's ends
double MdgranLaw::mean_force_t(double ta, double tb) const
{
  double mid = 0.5 * (ta + tb), half = 0.5 * (tb - ta);
  double num = 0.0, den = 0.0;
  for (int k = 0; k < 5; k++) {
    double tau = mid + half * GL_X[k];
    double t3 = tau * tau * tau;
    double wk = GL_W[k] * (t3 - sigma);
    double uu = t3 - 3.0 * sigma;
    num += wk * (fc + uu * uu);
    den += wk;
  }
  if (den <= 0.0) {
    double uu = ta * ta * ta - 3.0 * sigma;
    return fc + uu * uu;
  }
  return num / den;
}

// Drift of the owned moving atoms of the front over the step h from its start, which it records
// first (xs, vs: the current x and v of each of them; aprev is the start's acceleration):
//   v = vs + h/2 a0 (= v_half),  x = xs + h v.   Ghosts follow by forward communication.
// It also leaves the owned atoms' u and w for the pass over h that follows (drift_h = h), the
// numbers that pass would compute from x and v: one read of LAMMPS's x and v rows (3 doubles
// per atom) fewer per step (when the front holds every owned atom; else the pass computes them
// for the few atoms it needs).
void FixMdgranChain::drift(double h)
{
  if (contacts_stale) build_contacts();    // runs and still are those of the current atoms
  select_front();    // the owned atoms of the front (the others are at rest: x, v stay)
  const std::vector<int> &runs_ = active_runs();
  double *x = flat(atom->x), *v = flat(atom->v);
  double *const xs_ = xs, *const vs_ = vs, *const u_ = u, *const w_ = w;    // members as
  const double *const aprev_ = aprev, *const x0_ = x0;                      // locals
  const double hh = 0.5 * h;
  for (size_t r = 0; r < runs_.size(); r += 2)
    for (int i = runs_[r]; i < runs_[r + 1]; i++) {
      xs_[i] = x[3 * i];
      vs_[i] = v[3 * i];
      double vh = vs_[i] + hh * aprev_[i];
      double x1 = xs_[i] + h * vh;
      x[3 * i] = x1;
      v[3 * i] = vh;
      u_[i] = x1 - x0_[i];
      w_[i] = vh + hh * aprev_[i];
    }
  for (int i : still) {
    xs_[i] = x[3 * i];
    vs_[i] = v[3 * i];
    u_[i] = x[3 * i] - x0_[i];
    w_[i] = v[3 * i] + hh * aprev_[i];
  }
  drift_h = front_all ? h : -1.0;    // a part of the chain: the pass computes u, w of its own
}

// The owned atoms' accelerations at the end of a pass of length h (located_pass: contact and
// kick forces by left atom), which become the next step's a0 (aprev), and the kick of the
// moving ones, v = v_half + h/2 a_kick (h = 0: v unchanged).  write_f: LAMMPS's force array
// gets the acceleration (mass 1) for its computes and dumps (forces_read).  One loop over the
// atoms (a separate kick loop cost ~15% of a step, memory traffic).
void FixMdgranChain::accelerate(double h, int write_f)
{
  if (extended) accelerate_t<true>(h, write_f);
  else accelerate_t<false>(h, write_f);
}

// Acceleration a and kick acceleration av of atom i (not a wall) from the forces of its left
// and right contacts (fl, fr; fvl, fvr with the mean-force kick), its displacement ui and
// velocity estimate wi: a = fl - fr - (k1 u + k3 u^3) (mass 1); EXT (unlike beads, substrate
// damping, excitations): a = (fl - fr [+ F_pulse] - g (k1 y + k3 y^3 + c_s (w - u_b'))) / m
// with y = u - u_b, at the time of set_drive_time.  k1_, k3_: the members k1, k3, which the
// caller's loop keeps in registers (read through this, a store to a double array may alias
// them, and they were reloaded at every atom)
template <bool EXT>
inline void FixMdgranChain::bead_acc(int i, double fl, double fr, double fvl, double fvr,
                                     double ui, double wi, double k1_, double k3_, double &a,
                                     double &av) const
{
  a = fl - fr;
  av = fvl - fvr;
  double sub = k1_ * ui + k3_ * ui * ui * ui;    // substrate: k1 u + k3 u^3
  if constexpr (EXT) {    // g (k1 u + k3 u^3 + c_s w), all over the bead's mass
    const tagint t = atom->tag[i];
    if (driven) {    // the substrate on u - u_b, w - u_b'; the pulse on its atom
      const double y = ui - now_ub;
      sub = k1_ * y + k3_ * y * y * y;
      wi = wi - now_vb;
      if (t == pulse_tag) {
        a += now_fp;
        av += now_fp;
      }
    }
    sub = (mixed ? m_on_site[t] : 1.0) * (sub + sub_damping * wi);
    const double im = mixed ? m_inv_mass[t] : 1.0;
    a = (a - sub) * im;
    av = (av - sub) * im;
  } else {
    a -= sub;
    av -= sub;
  }
}

// accelerate of the homogeneous chain (EXT false) or of unlike beads or a damped substrate
template <bool EXT> void FixMdgranChain::accelerate_t(double h, int write_f)
{
  double *v = flat(atom->v), *f = flat(atom->f);
  double *const aprev_ = aprev;    // members as locals (see located_pass)
  const double *const fcon_ = fcon, *const fkick_ = fkick, *const u_ = u, *const w_ = w;
  const int *const left_ = left;
  const double k1_ = k1, k3_ = k3;
  const double hh = 0.5 * h;
  double check = 0.0;
  auto accel = [&](int i, double &a, double &av) {
    double fl = left_[i] >= 0 ? fcon_[left_[i]] : 0.0;
    double fvl = left_[i] >= 0 ? fkick_[left_[i]] : 0.0;
    bead_acc<EXT>(i, fl, fcon_[i], fvl, fkick_[i], u_[i], w_[i], k1_, k3_, a, av);
    check += a * 0.0 + av * 0.0;    // 0, unless some a or av is not finite (NaN then)
  };
  const std::vector<int> &runs_ = active_runs();    // the front's (the others keep a = 0)
  for (size_t r = 0; r < runs_.size(); r += 2)
    for (int i = runs_[r]; i < runs_[r + 1]; i++) {
      double a, av;
      accel(i, a, av);
      aprev_[i] = a;
      v[3 * i] = v[3 * i] + hh * av;
      if (write_f) f[3 * i] += a;
    }
  for (int i : still) {    // walls (a = 0) and atoms outside the fix group (not moved)
    const tagint t = atom->tag[i];
    if (!front_all && !is_wall(t) && (t < front_lo || t > front_hi)) continue;    // at rest
    double a = 0.0, av = 0.0;
    if (!is_wall(t)) accel(i, a, av);
    aprev[i] = a;
  }
  if (check != 0.0) {    // rare: find the first bead with a non-finite force
    for (int i = 0; i < atom->nlocal; i++) {
      double a = 0.0, av = 0.0;
      if (!is_wall(atom->tag[i])) accel(i, a, av);
      if (!std::isfinite(a) || !std::isfinite(av))
        error->one(FLERR, "non-finite force at t = {:.12g}, bead {}",
                   update->ntimestep * update->dt, walls ? atom->tag[i] - 1 : atom->tag[i]);
    }
  }
}

// Forces at the current positions for a pass of length h (v holds v_half; h = 0: an instant,
// v the actual velocities): contact forces fcon and kick forces fkick (by left atom) for
// accelerate, contacts that may switch (flagged, h > 0).  Returns this rank's damping power
// P = c sum (d delta/dt)^2 over its own closed contacts.
double FixMdgranChain::located_pass(double h)
{
  return mixed ? located_pass_t<true>(h) : located_pass_t<false>(h);
}

// located_pass with the chain's one law (MIX false) or each contact's own (unlike beads)
template <bool MIX> double FixMdgranChain::located_pass_t(double h)
{
  ncompute++;
  const int nall = atom->nlocal + atom->nghost;
  tagint *tag = atom->tag;
  const double *x = flat(atom->x), *v = flat(atom->v);
  const double hh = 0.5 * h;
  // members as locals (name_): the compiler cannot tell that the stores below leave the
  // members unchanged, and reloaded them at every contact
  double *const u_ = u, *const w_ = w, *const fcon_ = fcon, *const fkick_ = fkick;
  const double *const closed_ = closed, *const aprev_ = aprev, *const x0_ = x0;
  const double gap_ = gap, damping_ = damping, delta_off_ = delta_off, sing_ = sing;
  auto set_uw = [&](int i) {
    u_[i] = x[3 * i] - x0_[i];
    w_[i] = v[3 * i] + hh * aprev_[i];    // v_est = v_half + h/2 a0
  };
  if (!front_all) {    // the atoms of the front's contacts, the ghosts, the others not moved
    for (int k : front_cons) {
      set_uw(cons[k].l);
      set_uw(cons[k].r);
    }
    for (int i = atom->nlocal; i < nall; i++) set_uw(i);
    for (int i : still) set_uw(i);
  } else if (h > 0.0)    // owned atoms: left by the drift over h, when nothing moved them since
    for (int i = h == drift_h ? atom->nlocal : 0; i < nall; i++) set_uw(i);
  else
    for (int i = 0; i < nall; i++) {
      u_[i] = x[3 * i] - x0_[i];
      w_[i] = v[3 * i];
    }
  for (int i : wall_atoms) u_[i] = w_[i] = 0.0;
  drift_h = -1.0;
  double power = 0.0;
  flagged.clear();
  kicks.clear();
  // every contact, or the front's (pick: their indices), in the order of cons (the power sums
  // the same terms, less exact zeros); one loop, not a function called from two loops, which
  // the compiler need not inline into both (the loop over every contact is the hot one)
  const Con *const con = cons.data();
  const int *const pick = front_all ? nullptr : front_cons.data();
  const int ncon = front_all ? (int) cons.size() : (int) front_cons.size();
  for (int q = 0; q < ncon; q++) {
    const Con &c = con[pick ? pick[q] : q];
    double d = u_[c.l] - u_[c.r] - gap_;
    double rate = w_[c.l] - w_[c.r];
    double F = 0.0, Fv = 0.0, g, gd;
    if (closed_[c.l] != 0.0) {
      double off = delta_off_;
      if constexpr (MIX) {
        off = mixed_located(c, d, h, F, Fv);
      } else {
        if (use_table && d > tab_delta_max)
          error->one(FLERR, "compression {:.4g} beyond the contact table (delta_max = {:g}) "
                     "at t = {:.12g}, contact {}", d, tab_delta_max,
                     update->ntimestep * update->dt, contact_number(tag[c.l]));
        F = located_force(d);
        Fv = F;
        if (h > 0.0 && d < sing_)    // near snap-off: the mean-force kick, after the loop
          kicks.push_back({c.l, ustart(c.l) - ustart(c.r) - gap_, d, rate});
      }
      if (damping_ != 0.0) {
        F += damping_ * rate;
        Fv += damping_ * rate;
        if (c.own) power += damping_ * rate * rate;
      }
      g = d - off;
      gd = rate;
    } else {
      g = -d;
      gd = -rate;
    }
    // a dip of g below 0 inside the step implies g1 < h/2 g'(h) (g is a parabola)
    if (h > 0.0 && (g < 0.0 || g < hh * gd)) flagged.push_back(c);
    fcon_[c.l] = F;
    fkick_[c.l] = Fv;
  }
  if (!kicks.empty()) finish_kicks();
  if (h > 0.0)    // the same test for the contacts between two ghosts (event windows)
    for (const Con &c : gcons) {
      const double d = u_[c.l] - u_[c.r] - gap_, rate = w_[c.l] - w_[c.r];
      const int cl = closed_[c.l] != 0.0;
      const double g = cl ? d - off_of(tag[c.l]) : -d, gd = cl ? rate : -rate;
      if (g < 0.0 || g < hh * gd) flagged.push_back(c);
    }
  const std::vector<int> &runs_ = active_runs();
  if (sub_damping != 0.0)    // the substrate's damping power, g c_s w^2 of the moving beads
    for (size_t q = 0; q < runs_.size(); q += 2)
      for (int i = runs_[q]; i < runs_[q + 1]; i++)
      {
        const double wi = driven ? w_[i] - now_vb : w_[i];    // base motion: w - u_b'
        power += (MIX ? m_on_site[tag[i]] : 1.0) * (sub_damping * wi * wi);
      }
  return power;
}

// located_pass of a closed unlike contact c at compression d: its force F = A f(d / L) and
// kick force Fv (the mean force near its snap-off, in its own units), its threshold returned
inline double FixMdgranChain::mixed_located(const Con &c, double d, double h, double &F,
                                            double &Fv) const
{
  const tagint jt = atom->tag[c.l];
  F = closed_force(jt, d);
  Fv = F;
  if (h > 0.0 && in_band(jt, d)) Fv = kick_force(jt, ustart(c.l) - ustart(c.r) - gap, d);
  return m_delta_off[jt];
}

// Force f(d) of the closed contact whose left atom has tag t (units eta; unlike beads
// A f(d / L)); a compression beyond the table stops the run
double FixMdgranChain::closed_force(tagint t, double d) const
{
  if (!mixed) {
    if (use_table && d > tab_delta_max)
      error->one(FLERR, "compression {:.4g} beyond the contact table (delta_max = {:g}) at "
                 "t = {:.12g}, contact {}", d, tab_delta_max, update->ntimestep * update->dt,
                 contact_number(t));
    return located_force(d);
  }
  const MdgranLaw &law = laws[m_cls[t]];
  const double u1 = d * m_inv_len[t];
  if (law.use_table && u1 > law.tab_delta_max)
    error->one(FLERR, "compression {:.4g} (own units) beyond the contact table (delta_max = "
               "{:g}) at t = {:.12g}, contact {}", u1, law.tab_delta_max,
               update->ntimestep * update->dt, contact_number(t));
  return m_scale[t] * law.located_force(u1);
}

// The kick forces Fv = 2 mean_force(d0, d) - f(d0) (+ c rate) of the pass's contacts in the
// band near snap-off (one law), by the pass's operations, their branch parameters inverted
// T_BLOCK at a time (t_of_delta_n: one inversion is a chain of dependent square roots and
// divisions; one by one in the pass, the kicks of an active chain cost ~1.5 ns a bead-step)
void FixMdgranChain::finish_kicks()
{
  constexpr int HALF = T_BLOCK / 2;
  double d[T_BLOCK], t[T_BLOCK];
  for (size_t b = 0; b < kicks.size(); b += HALF) {
    const int n = (int) std::min<size_t>(HALF, kicks.size() - b);
    for (int j = 0; j < n; j++) {
      d[j] = kicks[b + j].d0;
      d[n + j] = kicks[b + j].d;
    }
    t_of_delta_n(d, t, 2 * n);
    for (int j = 0; j < n; j++) {
      const Kick &k = kicks[b + j];
      double Fv = 2.0 * mean_force_t(t[j], t[n + j]) - located_force(k.d0);
      if (damping != 0.0) Fv += damping * k.rate;
      fkick[k.l] = Fv;
    }
  }
}

// Whether closed contact t at compression d gets the mean-force kick (never for Hertz): in its
// law's band delta < delta_min + SING_BAND, in its own units when mixed
int FixMdgranChain::in_band(tagint t, double d) const
{
  if (!mixed) return d < sing;
  return d * m_inv_len[t] < laws[m_cls[t]].sing;
}

// Kick force of closed contact t over a (sub)step from compression d0 to d:
// Fv = 2 (V(d) - V(d0)) / (d - d0) - f(d0), so that h/2 (f(d0) + Fv) = h f_mean
double FixMdgranChain::kick_force(tagint t, double d0, double d) const
{
  if (!mixed) return 2.0 * mean_force(d0, d) - located_force(d0);
  const MdgranLaw &law = laws[m_cls[t]];
  const double il = m_inv_len[t], u0 = d0 * il, u1 = d * il;
  return m_scale[t] * (2.0 * law.mean_force(u0, u1) - law.located_force(u0));
}

// First s in [0, h] where the event function g(s) = g0 + s g0' + s^2/2 g0'' of a contact falls
// to min(g0, 0), or -1 (mdgran/backends/fast_kernel.py first_root): g = delta - off closed,
// -delta open (positive inside the state), from the compression d0, its rate b and second
// derivative q at the (sub)step's start and the compression d1 at its end (units p, 1/q).
static double event_root(int is_closed, double off, double d0, double b, double q, double d1,
                         double h)
{
  double g0 = d0, g1;
  if (is_closed) {
    g0 -= off;
    g1 = d1 - off;
  } else {
    g0 = -g0;
    b = -b;
    q = -q;
    g1 = -d1;
  }
  double cq = 0.5 * q;
  if (g0 <= 0.0) {    // on its switching point: an event if it moves out
    if (b < 0.0 || g0 < -STATE_TOL) return 0.0;
    if (cq < 0.0 && -b / cq <= h) return -b / cq;
    return g1 < g0 ? h : -1.0;
  }
  double s = -1.0;
  if (cq == 0.0) {
    if (b < 0.0) s = -g0 / b;
  } else {
    double disc = b * b - 4.0 * cq * g0;
    if (disc >= 0.0) {
      double qq = -0.5 * (b + std::copysign(std::sqrt(disc), b));
      double r1 = qq / cq;
      double r2 = qq != 0.0 ? g0 / qq : -1.0;
      if (r1 > 0.0 && (r2 <= 0.0 || r1 < r2)) s = r1;
      else if (r2 > 0.0) s = r2;
    }
  }
  if (s >= 0.0 && s <= h) return s;
  if (g1 < 0.0) return h;    // out at the end, rounding put the root past h
  return -1.0;
}

// event_root of contact c over the pass of length h: from the step's start (xs, vs, aprev) to
// the end of the pass (u)
double FixMdgranChain::first_root(const Con &c, double h) const
{
  return event_root(closed[c.l] != 0.0, off_of(atom->tag[c.l]),
                    ustart(c.l) - ustart(c.r) - gap, vstart(c.l) - vstart(c.r),
                    astart(c.l) - astart(c.r), u[c.l] - u[c.r] - gap, h);
}

void FixMdgranChain::add_visc(double dv)
{
  if (comm->nprocs == 1) d_visc_all += dv;
  else d_visc += dv;
}

// an event of the contact whose left atom has tag left (recorded by the left atom's owner)
void FixMdgranChain::add_event(tagint left, int kind, double time, double lost)
{
  Event e = {update->ntimestep, left, kind, time};
  if (comm->nprocs == 1) {
    d_hyst_all += lost;
    ev_all.push_back(e);
  } else {
    d_hyst += lost;
    ev_local.push_back(e);
  }
  size_array_rows = event_rows();
}

// Switch contact c at the current positions (the set-up's settle): opening loses V(delta)
// (exact law) to D_hysteresis; the new forces follow from the next pass.
void FixMdgranChain::switch_contact(const Con &c, double time)
{
  double d = disp(c.l) - disp(c.r) - gap;
  if (closed[c.l] != 0.0) {
    closed[c.l] = 0.0;
    if (c.own) add_event(atom->tag[c.l], 0, time,
                         mixed ? mixed_energy(atom->tag[c.l], d) : law_energy(d));
  } else {
    closed[c.l] = 1.0;
    if (c.own) add_event(atom->tag[c.l], 1, time, 0.0);
  }
}

// Switch again, at once, every contact of `list` on or over its switching point and moving
// outward (g <= 0, g' < 0), or beyond it by more than STATE_TOL (the reference's rule), with
// the actual velocities; more than MAX_SWITCHES switches of one contact stop the run.
void FixMdgranChain::settle(std::vector<int> &list, double time)
{
  std::vector<int> count(list.size(), 1);
  double **v = atom->v;
  auto vel = [&](int i) { return is_wall(atom->tag[i]) ? 0.0 : v[i][0]; };
  for (int moved = 1; moved;) {
    moved = 0;
    for (size_t k = 0; k < list.size(); k++) {
      const Con &c = cons[list[k]];
      double d = disp(c.l) - disp(c.r) - gap;
      double rate = vel(c.l) - vel(c.r);
      double g = closed[c.l] != 0.0 ? d - off_of(atom->tag[c.l]) : -d;
      double gd = closed[c.l] != 0.0 ? rate : -rate;
      if (g < -STATE_TOL || (g <= 0.0 && gd < 0.0)) {
        if (++count[k] > MAX_SWITCHES)
          error->one(FLERR, "contact {} chatters at t = {:.12g}: it switches state more than "
                     "{} times at one instant", contact_number(atom->tag[c.l]), time,
                     MAX_SWITCHES);
        switch_contact(c, time);
        moved = 1;
      }
    }
  }
}

// ---- the activity front ----------------------------------------------------------------------
//
// (mdgran/backends/fast_kernel.py at_rest, moving_hull, advance_front; docs/fast.md.)  An atom
// at rest (v and a +0.0: a -0.0 would turn into +0.0 in a step; x not -0.0, which the drift's
// x + h 0 would turn into +0.0) whose neighbours are at rest too is a fixed point of the step:
// the drift leaves its x and v, the pass gives its contacts the forces they had and so the
// atom the acceleration and kick it had, bit for bit.  A disturbance reaches one contact
// further per force evaluation, so the atoms not at rest lie in a range of tags, the front,
// that grows by at most one atom per step on each side.  Each rank steps (drift, pass, kick)
// the moving atoms it owns in its front and evaluates the contacts with one of them (and every
// contact between two ghosts, a few, for the event windows); the other atoms keep x, v, a and
// LAMMPS's force 0 (a = +0.0), as stepping them would leave them.  The sums over contacts and
// atoms (damping power) run over the same terms in the same order, less exact zeros; so the
// results are those of stepping every atom, bit for bit.
//
// Each rank tracks its own front, over the atoms it holds, without any collective call:
//   * the first step of a run steps every atom; its front is then the owned atoms not at rest
//     at that step's start or end, and one more on each side;
//   * after every step it takes in the step's event windows and their neighbours (a window
//     may write an atom outside it: a neighbour across a closed edge), then grows while its
//     edge atom or the one beyond, owned, is not at rest;
//   * before every pass it takes in each ghost not at rest at the step's start (the forwarded
//     xs, vs, aprev) and its neighbours: an owned atom next to it must be stepped in this pass
//     (a ghost that starts moving during a step moves the owned atoms next to it from the next
//     pass on, and is seen by then);
//   * at re-neighbouring it takes in every owned atom not at rest at the step's start (one
//     may arrive from another rank moving);
//   * a pulse's atom and its neighbours are always in it; with a base motion every atom is.
// It only grows, until the next run.  The atoms outside it are at rest since the run's first
// step, with xs = x and vs = v (from that step's drift), which the event windows read.  Once it
// holds every owned atom (a thermal chain) the loops are those over all of them (runs, cons).

// Atom i at rest with position x[stride i], velocity v[stride i] and acceleration aprev[i]
// (walls: always)
inline int FixMdgranChain::rest_at(int i, const double *x, const double *v, int stride) const
{
  if (is_wall(atom->tag[i])) return 1;
  const double xi = x[stride * i], vi = v[stride * i], ai = aprev[i];
  return vi == 0.0 && ai == 0.0 && !std::signbit(vi) && !std::signbit(ai) &&
      (xi != 0.0 || !std::signbit(xi));
}

// First and last tag of the owned atoms not at rest (lo > hi: none)
void FixMdgranChain::owned_hull(const double *x, const double *v, int stride, tagint &lo,
                                tagint &hi) const
{
  lo = ntags + 1;
  hi = 0;
  for (int i = 0; i < atom->nlocal; i++)
    if (!rest_at(i, x, v, stride)) {
      lo = std::min(lo, atom->tag[i]);
      hi = std::max(hi, atom->tag[i]);
    }
}

// The range lo .. hi (lo > hi: empty) joined with a .. b
static void take_in(tagint &lo, tagint &hi, tagint a, tagint b)
{
  if (lo > hi) {
    lo = a;
    hi = b;
  } else {
    lo = std::min(lo, a);
    hi = std::max(hi, b);
  }
}

// The atoms this step drifts, evaluates and kicks: the owned moving atoms of the front (every
// one, front_all) -- the vector's 7th element sums them over the steps and ranks (bead-steps)
void FixMdgranChain::count_bead_steps()
{
  const std::vector<int> &r = front_all ? runs : front_runs;
  for (size_t k = 0; k + 1 < r.size(); k += 2) bead_steps += r[k + 1] - r[k];
}

// front_all, or the owned moving atoms of the front as runs of local indices in increasing
// order (the order of runs, which the sums over atoms follow)
void FixMdgranChain::select_front()
{
  front_all = !front_known || (front_lo <= own_lo && front_hi >= own_hi);
  front_runs.clear();
  if (front_all) return;
  std::vector<int> &ids = front_ids;
  ids.clear();
  const int nlocal = atom->nlocal;
  for (tagint t = std::max(front_lo, own_lo); t <= std::min(front_hi, own_hi); t++) {
    const int i = atom->map(t);
    if (i >= 0 && i < nlocal && moves(i)) ids.push_back(i);
  }
  if (!std::is_sorted(ids.begin(), ids.end())) std::sort(ids.begin(), ids.end());
  for (int i : ids) {
    if (!front_runs.empty() && front_runs.back() == i) front_runs.back() = i + 1;
    else front_runs.insert(front_runs.end(), {i, i + 1});
  }
}

// The contacts of the front's atoms (left tags front_lo - 1 .. front_hi) that this rank
// evaluates, as indices into cons in increasing order (the order of the full pass)
void FixMdgranChain::select_front_contacts()
{
  front_cons.clear();
  if (front_all) return;
  const tagint a = std::max(front_lo - 1, known_lo), b = std::min(front_hi, known_hi);
  for (tagint t = a; t <= b; t++) {
    const int i = atom->map(t);
    if (i >= 0 && con_of[i] >= 0) front_cons.push_back(con_of[i]);
  }
  if (!std::is_sorted(front_cons.begin(), front_cons.end()))
    std::sort(front_cons.begin(), front_cons.end());
}

// At re-neighbouring (atoms have migrated, after this step's drift): every owned atom not at
// rest at the step's start, and its neighbours, so that an atom that arrives moving is in the
// front (its former owner's ghost, this rank saw it at rest at the last step's start, or
// already took it in); one loop over the owned atoms, as re-neighbouring is
void FixMdgranChain::front_take_arrivals()
{
  if (!front_known) return;
  tagint lo, hi;
  owned_hull(xs, vs, 1, lo, hi);
  if (lo <= hi) take_in(front_lo, front_hi, lo - 1, hi + 1);
}

// Before the pass: every ghost not at rest at the step's start, and its neighbours
void FixMdgranChain::widen_front_by_ghosts()
{
  const int nlocal = atom->nlocal, nall = nlocal + atom->nghost;
  for (int i = nlocal; i < nall; i++)
    if (!rest_at(i, xs, vs, 1)) take_in(front_lo, front_hi, atom->tag[i] - 1, atom->tag[i] + 1);
}

// After the step (the windows' end states committed): the front for the next one
void FixMdgranChain::advance_front()
{
  if (based) {    // a base motion moves every atom
    front_known = 1;
    front_lo = 1;
    front_hi = ntags;
    return;
  }
  const double *x = flat(atom->x), *v = flat(atom->v);
  tagint lo = front_lo, hi = front_hi;
  if (!front_known) {    // the run's first step: the atoms not at rest at its start or end
    owned_hull(x, v, 3, lo, hi);
    if (hull_lo <= hull_hi) take_in(lo, hi, hull_lo, hull_hi);
    if (lo <= hi) {
      lo--;
      hi++;
    }
  } else {
    for (const Window &wn : wins) take_in(lo, hi, wn.lo - 1, wn.hi + 1);
    // an atom not owned here counts as at rest: its owner steps it, and this rank sees it as a
    // ghost before the next pass
    auto rest = [&](tagint t) {
      const int i = atom->map(t);
      return i < 0 || i >= atom->nlocal || rest_at(i, x, v, 3);
    };
    if (lo <= hi) {
      lo = std::max<tagint>(lo, 1);
      hi = std::min(hi, ntags);
      while (hi < ntags && !(rest(hi) && rest(hi + 1))) hi++;
      while (lo > 1 && !(rest(lo) && rest(lo - 1))) lo--;
    }
  }
  if (pulse_tag) take_in(lo, hi, pulse_tag - 1, pulse_tag + 1);
  front_lo = lo;
  front_hi = hi;
  front_known = 1;
}

// The moved hull (vector 4 and 5: first and last tag, lo > hi: none): every atom that any step
// changed (the front after each step holds them) or that a run's set-up found not at rest or
// away from its initial position (x != x0 + 0.0).  Outside it every atom sits at x0 with v and
// a +0.0 and its contacts in their initial state, so a reader needs only the atoms in it.
void FixMdgranChain::take_in_moved_state()
{
  const double *x = flat(atom->x), *v = flat(atom->v);
  for (int i = 0; i < atom->nlocal; i++) {
    if (is_wall(atom->tag[i])) continue;
    const double d = x[3 * i] - x0[i];
    if (!rest_at(i, x, v, 3) || d != 0.0 || std::signbit(d))
      take_in(moved_lo, moved_hi, atom->tag[i], atom->tag[i]);
  }
}

// LAMMPS's force array gets the acceleration (mass 1) of the current state (thermo, dumps)
void FixMdgranChain::initial_integrate(int /*vflag*/)
{
  if (located) drift(update->dt);
  else nve(1);
}

void FixMdgranChain::final_integrate()
{
  nve(0);
}

// Quantized with "integrate yes": fix nve's velocity Verlet for the atoms this fix moves (runs),
// along x (the chain has no y or z velocity or force), with fix nve's operations, so that the
// run is bitwise the run with fix nve: v += dtf/m f, then (first half) x += dt v.  One loop over
// the moving atoms each half, without fix nve's mask test and y, z components (~2 ns per
// bead-step less at N = 1e5).  The first half also leaves the owned atoms' u and w for this
// step's compute (drift_h = dt), the numbers it would compute from x and v (as drift does).
void FixMdgranChain::nve(int first)
{
  if (contacts_stale) build_contacts();    // runs are those of the current atoms
  double *x = flat(atom->x), *v = flat(atom->v);
  const double *f = flat(atom->f);
  const double *rmass = atom->rmass, *mass = atom->mass;
  const int *type = atom->type;
  double *const u_ = u, *const w_ = w;    // members as locals (see located_pass)
  const double *const x0_ = x0, *const aprev_ = aprev;
  const double dtv = update->dt, dtf = 0.5 * update->dt * force->ftm2v, hdt = 0.5 * dtv;
  for (size_t r = 0; r < runs.size(); r += 2)
    for (int i = runs[r]; i < runs[r + 1]; i++) {
      double dtfm = rmass ? dtf / rmass[i] : dtf / mass[type[i]];
      double vi = v[3 * i] + dtfm * f[3 * i];
      v[3 * i] = vi;
      if (first) {
        double xi = x[3 * i] + dtv * vi;
        x[3 * i] = xi;
        u_[i] = xi - x0_[i];
        w_[i] = vi + hdt * aprev_[i];
      }
    }
  if (!first) return;
  for (int i : still) {
    u_[i] = x[3 * i] - x0_[i];
    w_[i] = v[3 * i] + hdt * aprev_[i];
  }
  drift_h = dtv;
}

// A run that goes on from the step the last one ended at keeps the activity front, so that a
// run in pieces of a few steps (mdgran's frames) steps what moves, not the whole chain at each
// piece's first step; unless an owned atom outside the front is no longer where that step
// left it, at rest (x = xs, v = vs: a command between the runs moved it).  One comparison
// per atom.
int FixMdgranChain::front_holds_still() const
{
  if (front_all) return 0;
  const double *x = flat(atom->x), *v = flat(atom->v);
  for (int i = 0; i < atom->nlocal; i++) {
    const tagint t = atom->tag[i];
    if (is_wall(t) || (t >= front_lo && t <= front_hi)) continue;
    if (x[3 * i] != xs[i] || v[3 * i] != vs[i] || !rest_at(i, x, v, 3)) return 0;
  }
  return 1;
}

// Set-up of a run: at the first one, settle every contact and compute a(0) and P(0) with the
// actual velocities; later ones (same step) hand LAMMPS the stored acceleration unchanged, so
// that a run in several pieces is the same as one.
void FixMdgranChain::located_setup()
{
  bigint step = update->ntimestep;
  if (!(have_last && step == last_step && front_known && front_holds_still())) {
    front_known = 0;    // the run's first step steps every atom
    front_all = 1;
  }
  if (!have_last || step != last_step) {
    build_contacts();
    comm->forward_comm(this);
    std::vector<int> all(cons.size());
    for (size_t k = 0; k < all.size(); k++) all[k] = (int) k;
    settle(all, (double) step * update->dt);
    comm->forward_comm(this);
    set_drive_time((double) step * update->dt);
    power_prev = located_pass(0.0);
    accelerate(0.0, 0);
    if (driven) work_prev = external_power();
    last_step = step;
    have_last = 1;
    take_in_moved_state();
  }
  double **f = atom->f;    // LAMMPS's force array gets the acceleration (mass 1)
  for (int i = 0; i < atom->nlocal; i++)
    if (moves(i)) f[i][0] += aprev[i];
}

// One step (post_force; initial_integrate has drifted the owned atoms of the front over dt from
// the step's start and LAMMPS has forwarded the ghosts' x and v): the front widened by the
// ghosts, the pass over it, the event windows stepped alone (local_events), the kick, the
// windows' end states in place of the pass's, the front for the next step, then the trapezoids
// of the damping power and of the excitations' power, each with what the windows' sub-steps
// change in it.
void FixMdgranChain::located_step()
{
  const bigint step = update->ntimestep;
  const double dt = update->dt;
  const double t0 = (double) (step - 1) * dt;
  if (contacts_stale) build_contacts();
  comm->forward_comm(this);    // ghosts: x0, state, the step's start (xs, vs, aprev)
  if (front_known) widen_front_by_ghosts();
  else owned_hull(xs, vs, 1, hull_lo, hull_hi);    // the start of the run's first step
  select_front();    // again: the ghosts may widen it, re-neighbouring renumbers the atoms
  select_front_contacts();
  count_bead_steps();
  set_drive_time(t0 + dt);
  const double p1 = located_pass(dt);
  double viscous = 0.0, power = 0.0, work_w = 0.0;    // the windows' changes (this rank's)
  wout.clear();
  wins.clear();
  if (!flagged.empty()) {
    local_events(t0, dt, viscous, power, work_w);
    set_drive_time(t0 + dt);
  }
  const int write_f = forces_read();
  accelerate(dt, write_f);
  if (!wout.empty()) commit_windows(write_f);
  advance_front();
  if (front_lo <= front_hi) take_in(moved_lo, moved_hi, front_lo, front_hi);
  add_visc(0.5 * dt * (power_prev + p1) + viscous);
  power_prev = p1 + power;
  if (driven) {    // the excitations' work, by the same rule (the fast backend's)
    const double pe = external_power();
    const double dw = 0.5 * dt * (work_prev + pe) + work_w;
    if (comm->nprocs == 1) work_all += dw;
    else work += dw;
    work_prev = pe;
  }
  last_step = step;
  have_last = 1;
}

// ---- event windows --------------------------------------------------------------------------
//
// (mdgran/backends/fast_kernel.py local_events and the functions it calls, in tags: bead t's
// left contact is t - 1, its right one t.)  The beads of the contacts whose event function has
// a root in the step form windows lo .. hi (two within two beads of each other are one).  A
// window is stepped again alone from the step's start (slots: copy 2 the start, copies 0 and 1
// the alternating sub-step states), through its events in time order, while its neighbours
// lo - 1 and hi + 1 move on their parabolas x + s v + s^2/2 a; an edge contact (to a
// neighbour) that switches, or is closed in the mean-force band, makes the window take that
// neighbour in and start again.  The neighbours are finished with the window's end force on
// the contact they share and take the difference between the window's impulse on it and the
// step's trapezoid, so that the contact's two beads get equal and opposite impulses (a
// neighbour across an open edge keeps the pass's numbers: the window's force on it is 0).
//
// Several ranks: every rank steps every window whose beads, neighbours and the beads within
// WINDOW_MARGIN of them it holds (owned or ghost), from the same numbers (ghosts: forwarded
// start state, forwarded x of the pass), in chain order; so a window across a rank boundary
// is stepped identically by both ranks, and each keeps the atoms it owns, logs the events of
// the contacts it owns and adds their damping power and its beads' excitation power.  A
// window that a rank owning an atom it writes cannot see whole stops the run (raise
// comm_modify cutoff).

inline int FixMdgranChain::slot_mine(int k) const
{
  return wi[k] < atom->nlocal;
}

// Tags owned here and held contiguously around them (owned and ghost), gathered from every
// rank (collective: at set-up and re-neighbouring, when the ghosts are made)
void FixMdgranChain::share_ranges()
{
  ntags = (tagint) atom->natoms;
  own_lo = ntags + 1;
  own_hi = 0;
  for (int i = 0; i < atom->nlocal; i++) {
    own_lo = std::min(own_lo, atom->tag[i]);
    own_hi = std::max(own_hi, atom->tag[i]);
  }
  known_lo = own_lo;
  known_hi = own_hi;
  while (known_lo > 1 && atom->map(known_lo - 1) >= 0) known_lo--;
  while (known_hi < ntags && atom->map(known_hi + 1) >= 0) known_hi++;
  if (comm->nprocs == 1) return;
  tagint mine[4] = {own_lo, own_hi, known_lo, known_hi};
  rank_ranges.resize(4 * (size_t) comm->nprocs);
  MPI_Allgather(mine, 4, MPI_LMP_TAGINT, rank_ranges.data(), 4, MPI_LMP_TAGINT, world);
}

// this rank holds every atom within WINDOW_MARGIN beads of window lo .. hi (the beads a
// neighbour's other contact and a window joining it need)
int FixMdgranChain::window_visible(tagint lo, tagint hi) const
{
  for (tagint t = std::max<tagint>(lo - WINDOW_MARGIN, 1);
       t <= std::min<tagint>(hi + WINDOW_MARGIN, ntags); t++)
    if (atom->map(t) < 0) return 0;
  return 1;
}

// The atoms a .. b that window lo .. hi writes: its beads, and each neighbour whose contact with
// it is closed (one that is open stays open through the step, or the window takes the
// neighbour in, and the neighbour keeps the pass's numbers, bit for bit); a contact whose state
// this rank does not hold counts as closed
void FixMdgranChain::window_writes(tagint lo, tagint hi, tagint &a, tagint &b) const
{
  a = lo;
  b = hi;
  if (lo - 1 >= 1 && !is_wall(lo - 1)) {
    const int i = atom->map(lo - 1);
    if (i < 0 || closed[i] != 0.0) a = lo - 1;
  }
  if (hi + 1 <= ntags && !is_wall(hi + 1)) {
    const int i = atom->map(hi);
    if (i < 0 || closed[i] != 0.0) b = hi + 1;
  }
}

// window lo .. hi writes an atom owned here
int FixMdgranChain::window_writes_owned(tagint lo, tagint hi) const
{
  tagint a, b;
  window_writes(lo, hi, a, b);
  for (tagint t = a; t <= b; t++) {
    const int i = atom->map(t);
    if (i >= 0 && i < atom->nlocal) return 1;
  }
  return 0;
}

// every rank owning an atom window lo .. hi writes holds the window with its margin (so that it
// steps the same window), or the run stops
void FixMdgranChain::check_window_ranks(tagint lo, tagint hi) const
{
  tagint wa_, wb_;
  window_writes(lo, hi, wa_, wb_);
  const tagint a = std::max<tagint>(lo - WINDOW_MARGIN, 1);
  const tagint b = std::min<tagint>(hi + WINDOW_MARGIN, ntags);
  for (int p = 0; p < comm->nprocs; p++) {
    const tagint *r = &rank_ranges[4 * (size_t) p];
    if (r[0] > wb_ || r[1] < wa_) continue;    // owns none of the atoms it writes
    if (a < r[2] || b > r[3])
      error->one(FLERR, "fix mdgran/chain: the event window of atoms {}..{} at step {} needs "
                 "atoms {}..{}, beyond those rank {} holds, {}..{} (raise comm_modify cutoff)",
                 lo, hi, update->ntimestep, a, b, p, r[2], r[3]);
  }
}

// The windows of the pass of length h: the beads of the flagged contacts with a root in the
// step, in chain order, two within two beads of each other joined
void FixMdgranChain::find_windows(double h)
{
  const tagint *tag = atom->tag;
  std::sort(flagged.begin(), flagged.end(),
            [&](const Con &a, const Con &b) { return tag[a.l] < tag[b.l]; });
  const tagint first = walls ? 2 : 1, last = walls ? ntags - 1 : ntags;    // moving beads
  wins.clear();
  for (const Con &c : flagged) {
    if (first_root(c, h) < 0.0) continue;
    const tagint lo = std::max(tag[c.l], first), hi = std::min(tag[c.l] + 1, last);
    if (!wins.empty() && lo <= wins.back().hi + 2) wins.back().hi = std::max(wins.back().hi, hi);
    else wins.push_back({lo, hi});
  }
}

// The slots of window lo .. hi (atoms lo - 2 .. hi + 2 of the chain) at the step's start, in
// copies 2 and 0 (walls: u = v = a = 0)
void FixMdgranChain::load_window(tagint lo, tagint hi)
{
  wbase = std::max<tagint>(lo - 2, 1);
  const int n = (int) (std::min<tagint>(hi + 2, ntags) - wbase + 1);
  wi.resize(n);
  wx0.resize(n);
  wve.resize(n);
  for (int c = 0; c < 3; c++) {
    wx[c].resize(n);
    wv[c].resize(n);
    wa[c].resize(n);
  }
  for (int k = 0; k < n; k++) {
    const int i = atom->map(wbase + k);
    if (i < 0)
      error->one(FLERR, "fix mdgran/chain: the event window of atoms {}..{} needs atom {}, "
                 "beyond the ghosts (raise comm_modify cutoff)", lo, hi, wbase + k);
    wi[k] = i;
    wx0[k] = x0[i];
    if (slot_wall(k)) {
      wx[2][k] = x0[i];
      wv[2][k] = wa[2][k] = 0.0;
    } else {
      if (!moves(i))
        error->one(FLERR, "fix mdgran/chain: an event window reaches atom {}, which is not in "
                   "the fix group", wbase + k);
      wx[2][k] = xs[i];
      wv[2][k] = vs[i];
      wa[2][k] = aprev[i];
    }
    wx[0][k] = wx[2][k];
    wv[0][k] = wv[2][k];
    wa[0][k] = wa[2][k];
  }
}

// Slot k's end of a Verlet (sub)step of length h from copy c: x, v_half and v_est (walls: at
// rest), the drift's operations
void FixMdgranChain::predict(int c, int k, double h, double &x, double &vh, double &ve) const
{
  if (slot_wall(k)) {
    x = wx0[k];
    vh = ve = 0.0;
    return;
  }
  const double hh = 0.5 * h, a = wa[c][k];
  vh = wv[c][k] + hh * a;
  x = wx[c][k] + h * vh;
  ve = vh + hh * a;
}

// The substrate damping power g c_s (w - u_b')^2 of slot k at velocity w (0 unless its bead is
// owned here)
double FixMdgranChain::bead_power(int k, double ve) const
{
  if (sub_damping == 0.0 || !slot_mine(k)) return 0.0;
  const double wv_ = driven ? ve - now_vb : ve;
  return (mixed ? m_on_site[wbase + k] : 1.0) * (sub_damping * wv_ * wv_);
}

// This rank's damping power in window lo .. hi at copy c (rates from v): its contacts, edges
// included, and its beads' substrate damping
double FixMdgranChain::window_power(int c, tagint lo, tagint hi) const
{
  double p = 0.0;
  if (damping != 0.0)
    for (tagint t = std::max<tagint>(lo - 1, 1); t <= std::min<tagint>(hi, ntags - 1); t++) {
      const int kl = slot(t);
      if (closed[wi[kl]] == 0.0 || !slot_mine(kl)) continue;
      const double r = wv[c][kl] - wv[c][kl + 1];
      p += damping * r * r;
    }
  for (tagint t = lo; t <= hi; t++) p += bead_power(slot(t), wv[c][slot(t)]);
  return p;
}

// This rank's share of the excitations' power on the window's beads at copy c (as
// external_power)
double FixMdgranChain::window_external(int c, tagint lo, tagint hi) const
{
  double p = 0.0, total = 0.0;
  for (tagint t = lo; t <= hi; t++) {
    const int k = slot(t);
    if (!slot_mine(k)) continue;
    if (t == pulse_tag) p += now_fp * wv[c][k];
    if (based) {
      const double y = slot_u(c, k) - now_ub;
      double fs = -(k1 * y + k3 * y * y * y + sub_damping * (wv[c][k] - now_vb));
      total += mixed ? m_on_site[t] * fs : fs;
    }
  }
  return p + now_vb * total;
}

// Force of contact t (left tag; 0: none) at copy c, damping rate from v
double FixMdgranChain::start_force(int c, tagint t) const
{
  if (t == 0) return 0.0;
  const int kl = slot(t);
  if (closed[wi[kl]] == 0.0) return 0.0;
  double f = closed_force(t, slot_u(c, kl) - slot_u(c, kl + 1) - gap);
  if (damping != 0.0) f += damping * (wv[c][kl] - wv[c][kl + 1]);
  return f;
}

// Finish slot k of a window sub-step of length h into copy n: its acceleration and end velocity
// v_half + h/2 a_v from its contact forces (fl, fr; fvl, fvr with the kick), as accelerate
void FixMdgranChain::finish_bead(int n, int k, double fl, double fr, double fvl, double fvr,
                                 double h)
{
  double a, av;
  if (extended) bead_acc<true>(wi[k], fl, fr, fvl, fvr, slot_u(n, k), wve[k], k1, k3, a, av);
  else bead_acc<false>(wi[k], fl, fr, fvl, fvr, slot_u(n, k), wve[k], k1, k3, a, av);
  wa[n][k] = a;
  wv[n][k] = wv[n][k] + 0.5 * h * av;
}

// One Verlet (sub)step of window lo .. hi of length h ending at t1, from copy c into 1 - c: its
// beads as the pass steps them (mean-force kick near snap-off included), its neighbours along
// their parabolas (v = v0 + h a, a unchanged).  Returns this rank's damping power at the end
// (rates from v_est), the forces of its edge contacts and which edge is closed in the band.
FixMdgranChain::WinPass FixMdgranChain::window_pass(int c, double h, double t1, tagint lo,
                                                    tagint hi)
{
  const int n = 1 - c;
  set_drive_time(t1);
  for (tagint t = std::max<tagint>(lo - 1, 1); t <= std::min<tagint>(hi + 1, ntags); t++) {
    const int k = slot(t);
    predict(c, k, h, wx[n][k], wv[n][k], wve[k]);
  }
  WinPass out = {0.0, 0.0, 0.0, 0};
  double f_l = 0.0, fv_l = 0.0;    // force of the contact left of the bead to finish next
  for (tagint t = std::max<tagint>(lo - 1, 1); t <= std::min<tagint>(hi, ntags - 1); t++) {
    const int kl = slot(t), kr = kl + 1;
    const double d = slot_u(n, kl) - slot_u(n, kr) - gap;
    const double rate = wve[kl] - wve[kr];
    const int edge = t < lo ? (slot_wall(kl) ? 0 : 1) : (t + 1 > hi && !slot_wall(kr) ? 2 : 0);
    double F = 0.0, Fv = 0.0;
    if (closed[wi[kl]] != 0.0) {
      F = closed_force(t, d);
      Fv = F;
      if (in_band(t, d)) {
        if (edge) out.band |= edge;
        else Fv = kick_force(t, slot_u(c, kl) - slot_u(c, kr) - gap, d);
      }
      if (damping != 0.0) {
        F += damping * rate;
        Fv += damping * rate;
        if (slot_mine(kl)) out.power += damping * rate * rate;
      }
    }
    if (edge == 1) out.f_left = F;
    else if (edge == 2) out.f_right = F;
    if (t >= lo) {
      finish_bead(n, kl, f_l, F, fv_l, Fv, h);
      out.power += bead_power(kl, wve[kl]);
    }
    f_l = F;
    fv_l = Fv;
  }
  if (hi == ntags) {    // the last bead of a chain without walls: no contact on its right
    finish_bead(n, slot(hi), f_l, 0.0, fv_l, 0.0, h);
    out.power += bead_power(slot(hi), wve[slot(hi)]);
  }
  for (tagint t : {lo - 1, hi + 1})    // the neighbours: on their parabolas
    if (t >= 1 && t <= ntags && !is_wall(t)) {
      const int k = slot(t);
      wv[n][k] = wve[k];
      wa[n][k] = wa[c][k];
    }
  return out;
}

// Earliest root te among contacts jl .. jr over the sub-step from copy c (its end in 1 - c),
// and the contacts switching with it (root within tol of te, in chain order) into sw; returns
// their number (0: none, te unchanged)
int FixMdgranChain::locate_window_events(int c, double h, double tol, tagint jl, tagint jr,
                                         std::vector<tagint> &sw, double &te)
{
  const int n = 1 - c;
  std::vector<double> &root = wroot;
  root.assign(jr - jl + 1, -1.0);
  double first = -1.0;
  for (tagint t = jl; t <= jr; t++) {
    const int kl = slot(t), kr = kl + 1;
    const double s = event_root(closed[wi[kl]] != 0.0, off_of(t),
                                slot_u(c, kl) - slot_u(c, kr) - gap, wv[c][kl] - wv[c][kr],
                                wa[c][kl] - wa[c][kr], slot_u(n, kl) - slot_u(n, kr) - gap, h);
    root[t - jl] = s;
    if (s >= 0.0 && (first < 0.0 || s < first)) first = s;
  }
  sw.clear();
  if (first < 0.0) return 0;
  for (tagint t = jl; t <= jr; t++)
    if (root[t - jl] >= 0.0 && root[t - jl] <= first + tol) sw.push_back(t);
  te = first;
  return (int) sw.size();
}

// Switch contact t at time `time` in copy c: the hysteresis loss V(delta) on opening, the
// event (logged once the step's windows are final), the change of force on its two beads'
// accelerations; returns the change of this rank's damping power.  The chatter guard: more
// than MAX_SWITCHES switches of one contact at one instant stop the run.
double FixMdgranChain::window_switch(int c, tagint t, double time)
{
  const int kl = slot(t), kr = kl + 1, l = wi[kl], mine = slot_mine(kl);
  const double d = slot_u(c, kl) - slot_u(c, kr) - gap;
  const double r = wv[c][kl] - wv[c][kr];
  double f_old = 0.0, f_new = 0.0, dp = 0.0;
  if (closed[l] != 0.0) {
    f_old = closed_force(t, d);
    if (damping != 0.0) {
      f_old += damping * r;
      if (mine) dp -= damping * r * r;
    }
    closed[l] = 0.0;
    pending.push_back({l, mine, 0, t, time, mixed ? mixed_energy(t, d) : law_energy(d)});
  } else {
    closed[l] = 1.0;
    pending.push_back({l, mine, 1, t, time, 0.0});
    f_new = closed_force(t, d);
    if (damping != 0.0) {
      f_new += damping * r;
      if (mine) dp += damping * r * r;
    }
  }
  const double df = f_new - f_old;
  if (!slot_wall(kl)) wa[c][kl] -= mixed ? df * m_inv_mass[t] : df;
  if (!slot_wall(kr)) wa[c][kr] += mixed ? df * m_inv_mass[t + 1] : df;
  if (std::fabs(time - chat_time) > SIMULTANEOUS * (1.0 + std::fabs(time))) {
    chat_time = time;
    chat.clear();
  }
  auto it = std::find_if(chat.begin(), chat.end(), [&](const auto &e) { return e.first == t; });
  if (it == chat.end()) chat.push_back({t, 1});
  else if (++it->second > MAX_SWITCHES)
    error->one(FLERR, "contact {} chatters at t = {:.12g}: it switches state more than {} times "
               "at one instant", contact_number(t), time, MAX_SWITCHES);
  return dp;
}

// Switch the located contacts sw at `time` in copy c, then switch again at once each one on or
// over its switching point and moving outward (g <= 0, g' < 0), or beyond it by more than
// STATE_TOL (the reference's rule), until none is; returns the change of the damping power
double FixMdgranChain::window_settle(int c, const std::vector<tagint> &sw, double time)
{
  double dp = 0.0;
  for (tagint t : sw) dp += window_switch(c, t, time);
  for (int moved = 1; moved;) {
    moved = 0;
    for (tagint t : sw) {
      const int kl = slot(t), kr = kl + 1;
      const double d = slot_u(c, kl) - slot_u(c, kr) - gap;
      const double r = wv[c][kl] - wv[c][kr];
      const int cl = closed[wi[kl]] != 0.0;
      const double g = cl ? d - off_of(t) : -d, gd = cl ? r : -r;
      if (g < -STATE_TOL || (g <= 0.0 && gd < 0.0)) {
        dp += window_switch(c, t, time);
        moved = 1;
      }
    }
  }
  return dp;
}

// (F, Fv) of contact t at the end of the pass of length h from the step's start (copy 2), by the
// pass's operations (the neighbour's other contact, which no window steps)
void FixMdgranChain::pass_force(tagint t, double h, double &F, double &Fv) const
{
  F = Fv = 0.0;
  const int kl = slot(t), kr = kl + 1;
  if (closed[wi[kl]] == 0.0) return;
  double xl, vhl, vel, xr, vhr, ver;
  predict(2, kl, h, xl, vhl, vel);
  predict(2, kr, h, xr, vhr, ver);
  const double ul = slot_wall(kl) ? 0.0 : xl - wx0[kl], ur = slot_wall(kr) ? 0.0 : xr - wx0[kr];
  const double d = ul - ur - gap, rate = vel - ver;
  F = closed_force(t, d);
  Fv = F;
  if (in_band(t, d)) Fv = kick_force(t, slot_u(2, kl) - slot_u(2, kr) - gap, d);
  if (damping != 0.0) {
    F += damping * rate;
    Fv += damping * rate;
  }
}

// Neighbour b of a window after the step h: its end acceleration and velocity from the
// window's end force f_edge on the contact they share and the pass's force on its other
// contact, its velocity given `impulse`, the window's impulse on the shared contact minus the
// step's trapezoid (equal and opposite impulses on the contact's two beads: momentum kept).
// window_left: the window is on b's left (the shared contact pushes b by +F).
void FixMdgranChain::finish_neighbour(tagint b, double h, double f_edge, double impulse,
                                      int window_left)
{
  const int k = slot(b);
  double x, vh, ve, fo = 0.0, fvo = 0.0, a, av;
  predict(2, k, h, x, vh, ve);
  double fl, fr, fvl, fvr, dj;
  if (window_left) {
    if (b <= ntags - 1) pass_force(b, h, fo, fvo);
    fl = fvl = f_edge;
    fr = fo;
    fvr = fvo;
    dj = impulse;
  } else {
    if (b - 1 >= 1) pass_force(b - 1, h, fo, fvo);
    fl = fo;
    fvl = fvo;
    fr = fvr = f_edge;
    dj = -impulse;
  }
  const double ub = x - wx0[k];
  if (extended) bead_acc<true>(wi[k], fl, fr, fvl, fvr, ub, ve, k1, k3, a, av);
  else bead_acc<false>(wi[k], fl, fr, fvl, fvr, ub, ve, k1, k3, a, av);
  const double v1 = vh + 0.5 * h * av + dj * (mixed ? m_inv_mass[b] : 1.0);
  if (slot_mine(k)) wout.push_back({wi[k], x, v1, a});
}

// Step window lo .. hi from the step's start (t0) through its events to t0 + dt, as the whole
// chain would be stepped (window_pass to the earliest root te of its contacts, which switch
// there, then the rest of the step in the new states, repeated); its owned beads' and
// neighbours' end states go into wout.  Returns nonzero (1 left, 2 right, 3 both; nothing
// written, switches pending) when an edge contact switches in the step or is closed in the
// mean-force band: the window must take in that neighbour.  Else `viscous` and `work` are what
// its sub-steps change in the step's trapezoids of the damping power and of the excitations'
// power, `power` what they change in its end power (this rank's shares).
int FixMdgranChain::resolve_window(tagint lo, tagint hi, double t0, double dt,
                                   double &viscous, double &power, double &work)
{
  load_window(lo, hi);
  const tagint jl = std::max<tagint>(lo - 1, 1), jr = std::min<tagint>(hi, ntags - 1);
  const tagint edge_l = lo - 1 >= 1 && !is_wall(lo - 1) ? lo - 1 : 0;    // 0: none
  const tagint edge_r = hi + 1 <= ntags && !is_wall(hi + 1) ? hi : 0;
  set_drive_time(t0);
  const double p_start = window_power(2, lo, hi);
  const double e_start = driven ? window_external(2, lo, hi) : 0.0;
  const double f0_l = start_force(2, edge_l), f0_r = start_force(2, edge_r);
  double p_state = p_start, e_state = e_start, fs_l = f0_l, fs_r = f0_r, j_l = 0.0, j_r = 0.0;
  const double tol = SIMULTANEOUS * (1.0 + std::fabs(t0));
  double done = 0.0, h = dt, visc = 0.0, w_sum = 0.0, p_pass = 0.0;
  int c = 0, redo = 0, nsub = 0, first = 1;
  chat.clear();
  chat_time = -1.0;
  for (;;) {
    const WinPass wp = window_pass(c, h, t0 + done + h, lo, hi);
    if (first) p_pass = wp.power;    // the window's share of the pass's power
    first = 0;
    if (wp.band) return wp.band;
    int ns = redo, last = 0;
    double te = h;
    if (redo == 0) {
      ns = locate_window_events(c, h, tol, jl, jr, wswitch, te);
      last = ns == 0 || te >= h - tol;
    }
    int grow = 0;    // an edge contact switches: take that neighbour in
    if (ns > 0)
      for (tagint t : wswitch) grow |= (t == edge_l ? 1 : 0) | (t == edge_r ? 2 : 0);
    if (grow) return grow;
    if (last || redo > 0) {    // keep this sub-step
      visc += 0.5 * h * (p_state + wp.power);
      if (driven) {
        const double e1 = window_external(1 - c, lo, hi);    // at t0 + done + h (window_pass)
        w_sum += 0.5 * h * (e_state + e1);
        e_state = e1;
      }
      j_l += 0.5 * h * (fs_l + wp.f_left);
      j_r += 0.5 * h * (fs_r + wp.f_right);
      p_state = wp.power;
      fs_l = wp.f_left;
      fs_r = wp.f_right;
      c = 1 - c;
    }
    if (ns == 0) break;
    if (redo == 0 && !last && te > 0.0) {    // step again, up to the event
      redo = ns;
      h = te;
      continue;
    }
    const double tev = last ? t0 + dt : t0 + done + te;
    p_state += window_settle(c, wswitch, tev);
    if (++nsub > MAX_SUBSTEPS)
      error->one(FLERR, "more than {} events in one step at t = {:.12g}", MAX_SUBSTEPS, tev);
    if (last) break;
    done += te;
    h = dt - done;
    redo = 0;
  }
  for (tagint t = lo; t <= hi; t++) {
    const int k = slot(t);
    if (slot_mine(k)) wout.push_back({wi[k], wx[c][k], wv[c][k], wa[c][k]});
  }
  set_drive_time(t0 + dt);
  // the neighbours across closed edges (an open edge leaves the pass's numbers: window_writes)
  if (edge_l && closed[wi[slot(edge_l)]] != 0.0)
    finish_neighbour(lo - 1, dt, fs_l, j_l - 0.5 * dt * (f0_l + fs_l), 0);
  if (edge_r && closed[wi[slot(edge_r)]] != 0.0)
    finish_neighbour(hi + 1, dt, fs_r, j_r - 0.5 * dt * (f0_r + fs_r), 1);
  viscous = visc - 0.5 * dt * (p_start + p_pass);
  power = p_state - p_pass;
  work = w_sum - 0.5 * dt * (e_start + e_state);
  return 0;
}

// Undo the switches logged since `mark` (latest first): the contacts' states back
void FixMdgranChain::undo_pending(size_t mark)
{
  while (pending.size() > mark) {
    const Pending &e = pending.back();
    closed[e.l] = closed[e.l] != 0.0 ? 0.0 : 1.0;
    pending.pop_back();
  }
}

// Window k widened by a bead on the side(s) `grow` asks (1 left, 2 right), joined with the
// windows after it that it comes within two beads of
void FixMdgranChain::widen(size_t k, int grow)
{
  if (grow & 1) wins[k].lo -= 1;
  if (grow & 2) wins[k].hi += 1;
  while (k + 1 < wins.size() && wins[k + 1].lo <= wins[k].hi + 2) {
    wins[k].hi = std::max(wins[k].hi, wins[k + 1].hi);
    wins.erase(wins.begin() + (long) k + 1);
  }
}

// The events of the step from t0 whose pass has just run, each window of them stepped alone
// in chain order (find_windows, resolve_window).  A window that must take in a neighbour is
// undone, widened and stepped again; one that comes within two beads of the window before it
// is joined with it, and the step's windows are all stepped again (rare).  Then the switches
// are logged, in time order (simultaneous ones by contact).  Returns this rank's changes to
// the step's trapezoids of the damping and excitation powers and to its end damping power.
void FixMdgranChain::local_events(double t0, double dt, double &viscous, double &power,
                                  double &work)
{
  find_windows(dt);
  pending.clear();
  size_t k = 0;
  while (k < wins.size()) {
    const tagint lo = wins[k].lo, hi = wins[k].hi;
    if (comm->nprocs > 1) {
      const int mine = window_writes_owned(lo, hi);
      if (mine) check_window_ranks(lo, hi);
      if (!window_visible(lo, hi)) {    // only at the ghosts' far end: not this rank's
        if (mine)
          error->one(FLERR, "fix mdgran/chain: the event window of atoms {}..{} at step {} "
                     "reaches beyond the ghosts (raise comm_modify cutoff)", lo, hi,
                     update->ntimestep);
        wins.erase(wins.begin() + (long) k);
        continue;
      }
    }
    const size_t mark = pending.size(), outs = wout.size();
    double dv, dp, dw;
    const int grow = resolve_window(lo, hi, t0, dt, dv, dp, dw);
    if (grow == 0) {
      viscous += dv;
      power += dp;
      work += dw;
      k++;
      continue;
    }
    undo_pending(mark);
    wout.resize(outs);
    widen(k, grow);
    if (k > 0 && wins[k].lo <= wins[k - 1].hi + 2) {    // reaches a window already stepped
      joins += 1.0;
      wins[k - 1].hi = wins[k].hi;
      wins.erase(wins.begin() + (long) k);
      widen(k - 1, 0);
      undo_pending(0);
      wout.clear();
      viscous = power = work = 0.0;
      k = 0;
    }
  }
  std::stable_sort(pending.begin(), pending.end(), [](const Pending &a, const Pending &b) {
    return a.time != b.time ? a.time < b.time : a.left < b.left;
  });
  for (const Pending &e : pending)
    if (e.own) add_event(e.left, e.kind, e.time, e.lost);
  pending.clear();
}

// The windows' end states of the owned atoms in place of the pass's: x, v, the acceleration
// (the next step's a0) and, when accelerate gave it the pass's (write_f), LAMMPS's force
// array
void FixMdgranChain::commit_windows(int write_f)
{
  double *x = flat(atom->x), *v = flat(atom->v), *f = flat(atom->f);
  for (const Out &o : wout) {
    x[3 * o.i] = o.x;
    v[3 * o.i] = o.v;
    if (write_f) f[3 * o.i] = (f[3 * o.i] - aprev[o.i]) + o.a;
    aprev[o.i] = o.a;
  }
}

// LAMMPS's force array is read at the end of this step, so a located step puts its
// accelerations there: output (thermo, dumps, restart files) is due, the run ends, or another
// fix runs after the forces (at post_force, final_integrate or end_of_step: fix ave/atom, fix
// print, fix halt ... whose computes and variables may read f).  Otherwise the array keeps
// LAMMPS's zeros: the fix moves the atoms with its own accelerations, and writing them on
// every step cost ~3 % of a step at 1e6 beads, on one rank and on two (a row of three doubles
// per atom through the memory bus).
int FixMdgranChain::forces_read() const
{
  const bigint step = update->ntimestep;
  return step == output->next || step == update->laststep || modify->n_post_force_any > 1 ||
         modify->n_final_integrate > 0 || modify->n_end_of_step > 0;
}

// ---- output -------------------------------------------------------------------------------

double FixMdgranChain::compute_scalar()
{
  if (energy_at == ncompute) return energy_cache;    // positions unchanged since then
  double e = 0.0;
  const int nlocal = atom->nlocal;
  ntags = (tagint) atom->natoms;
  std::vector<double> deltas;    // of the closed contacts, in order
  for (int i = 0; i < nlocal; i++) {
    if (closed[i] == 0.0 || atom->tag[i] >= (tagint) atom->natoms) continue;
    int j = atom->map(atom->tag[i] + 1);
    if (j < 0) continue;
    double delta = disp(i) - disp(j);
    if (gap != 0.0) delta = delta - gap;
    deltas.push_back(delta);
  }
  // e += law_energy(delta) in that order, the branch parameters T_BLOCK at a time
  double t[T_BLOCK];
  if (mixed) {    // each contact's own law (its left atom's tag, in the same order)
    size_t k = 0;
    for (int i = 0; i < nlocal; i++) {
      if (closed[i] == 0.0 || atom->tag[i] >= (tagint) atom->natoms) continue;
      if (atom->map(atom->tag[i] + 1) < 0) continue;
      e += mixed_energy(atom->tag[i], deltas[k++]);
    }
    deltas.clear();
  }
  for (size_t b = 0; b < deltas.size(); b += T_BLOCK) {
    const int n = (int) std::min<size_t>(T_BLOCK, deltas.size() - b);
    if (!hertz) t_of_delta_n(&deltas[b], t, n);
    for (int k = 0; k < n; k++)
      e += hertz ? law_energy(deltas[b + k]) : antiderivative(t[k]) - p_t0;
  }
  double ub = 0.0, vb, fp;    // the base's displacement now (0 without one)
  if (located && based) drive_at((double) update->ntimestep * update->dt, ub, vb, fp);
  if (located)    // the substrate is this fix's too: k1 u^2 / 2 + k3 u^4 / 4
    for (int i = 0; i < nlocal; i++) {
      if (!moves(i)) continue;
      double ui = atom->x[i][0] - x0[i];
      if (based) ui = ui - ub;
      double es = 0.5 * k1 * ui * ui + 0.25 * k3 * ui * ui * ui * ui;
      e += mixed ? m_on_site[atom->tag[i]] * es : es;
    }
  double all = e;
  if (comm->nprocs > 1) MPI_Allreduce(&e, &all, 1, MPI_DOUBLE, MPI_SUM, world);
  energy_at = ncompute;
  energy_cache = all;
  return all;
}

// global outputs are called on every rank at once (thermo, the library interface), so they may
// sync (collective) when the step has changed since the last sync
double FixMdgranChain::compute_vector(int n)
{
  if (comm->nprocs > 1 && synced_step != update->ntimestep) sync();
  if (n == 0) return d_hyst_all;
  if (n == 1) return d_visc_all;
  if (n == 2) return (double) event_rows();
  if (n == 3) return work_all;
  if (n == 6) return comm->nprocs > 1 ? bead_steps_all : bead_steps;
  if (n == 7) return comm->nprocs > 1 ? joins_all : joins;
  if (!located) return n == 4 ? 1.0 : (double) ntags;    // every atom is stepped
  if (comm->nprocs > 1) return moved_all[n - 4];
  return n == 4 ? (double) moved_lo : (double) moved_hi;
}

double FixMdgranChain::compute_array(int row, int col)
{
  if (comm->nprocs > 1 && synced_step != update->ntimestep) sync();
  if (row < ev_first || row >= event_rows()) return 0.0;    // released, or beyond the last
  const Event &e = ev_all[row - ev_first];
  if (col == 0) return e.time;
  if (col == 1) return (double) contact_number(e.left);
  if (col == 2) return (double) e.kind;
  return (double) e.step;
}

// Rows first .. first + count - 1 of the global array (time, contact, kind, step) into out,
// 4 doubles a row, the values compute_array gives one at a time (read that way through
// LAMMPS's library interface, an event cost ~10 us in Python: an active chain of 1e5 beads
// has ~1e4 a time unit).  Collective on several ranks, as compute_array.  Returns the rows
// copied (fewer than count past the last), -1 if first is a released row.
int FixMdgranChain::copy_events(int first, int count, double *out)
{
  if (comm->nprocs > 1 && synced_step != update->ntimestep) sync();
  if (first < ev_first) return -1;
  const int n = std::max(0, std::min(count, event_rows() - first));
  for (int k = 0; k < n; k++)
    for (int col = 0; col < 4; col++) out[4 * k + col] = compute_array(first + k, col);
  return n;
}

// The rows before end released (a reader that has copied them, the backend after each frame):
// the fix then holds the events since, not every event of the run (an active chain of 1e6
// beads has ~1e5 a time unit, 24 bytes each on every rank).  Their rows read 0 afterwards;
// the count (f_ID[3]) and the later rows' numbers stay.
void FixMdgranChain::drop_events(int end)
{
  const bigint n = std::min<bigint>(end - ev_first, (bigint) ev_all.size());
  if (n <= 0) return;
  ev_all.erase(ev_all.begin(), ev_all.begin() + n);
  ev_first += n;
}

// ---- per-atom state: growth, migration, restart, ghosts ---------------------------------

void FixMdgranChain::grow_arrays(int nmax)
{
  memory->grow(x0, nmax, "mdgran/chain:x0");
  memory->grow(closed, nmax, "mdgran/chain:closed");
  memory->grow(dprev, nmax, "mdgran/chain:dprev");
  memory->grow(aprev, nmax, "mdgran/chain:aprev");
  memory->grow(xs, nmax, "mdgran/chain:xs");
  memory->grow(vs, nmax, "mdgran/chain:vs");
  vector_atom = closed;
}

void FixMdgranChain::copy_arrays(int i, int j, int /*delflag*/)
{
  x0[j] = x0[i];
  closed[j] = closed[i];
  dprev[j] = dprev[i];
  aprev[j] = aprev[i];
  xs[j] = xs[i];
  vs[j] = vs[i];
}

int FixMdgranChain::pack_exchange(int i, double *buf)
{
  buf[0] = x0[i];
  buf[1] = closed[i];
  buf[2] = dprev[i];
  buf[3] = aprev[i];
  buf[4] = xs[i];
  buf[5] = vs[i];
  return NEXCHANGE;
}

int FixMdgranChain::unpack_exchange(int nlocal, double *buf)
{
  x0[nlocal] = buf[0];
  closed[nlocal] = buf[1];
  dprev[nlocal] = buf[2];
  aprev[nlocal] = buf[3];
  xs[nlocal] = buf[4];
  vs[nlocal] = buf[5];
  return NEXCHANGE;
}

int FixMdgranChain::pack_restart(int i, double *buf)
{
  buf[0] = NPERATOM + 1;    // values of this fix, this count included
  buf[1] = x0[i];
  buf[2] = closed[i];
  buf[3] = dprev[i];
  buf[4] = aprev[i];
  return NPERATOM + 1;
}

void FixMdgranChain::unpack_restart(int nlocal, int nth)
{
  double **extra = atom->extra;
  int m = 0;    // skip the values of the fixes stored before this one
  for (int k = 0; k < nth; k++) m += static_cast<int>(extra[nlocal][m]);
  const double *buf = &extra[nlocal][m + 1];
  x0[nlocal] = buf[0];
  closed[nlocal] = buf[1];
  dprev[nlocal] = buf[2];
  aprev[nlocal] = buf[3];
  xs[nlocal] = atom->x[nlocal][0];
  vs[nlocal] = atom->v[nlocal][0];
}

int FixMdgranChain::size_restart(int /*nlocal*/)
{
  return NPERATOM + 1;
}

int FixMdgranChain::maxsize_restart()
{
  return NPERATOM + 1;
}

// global state: totals over the ranks (every rank calls this; rank 0 writes; every rank
// reads, rank 0 keeps the sums: the damping power of the last step is a sum over the ranks'
// contacts, and the trapezoid of the next step adds it once)
void FixMdgranChain::write_restart(FILE *fp)
{
  // driven: then the external work and its rate (likewise)
  double part[5] = {d_hyst, d_visc, power_prev, work, work_prev};
  double sum[5] = {d_hyst, d_visc, power_prev, work, work_prev};
  if (comm->nprocs > 1) MPI_Allreduce(part, sum, 5, MPI_DOUBLE, MPI_SUM, world);
  const int nvalues = driven ? 7 : 5;    // after the mark and the count
  double list[9] = {RESTART_MARK, (double) nvalues, d_hyst_all + sum[0], d_visc_all + sum[1],
                    sum[2], (double) last_step, (double) have_last, work_all + sum[3], sum[4]};
  const int nlist = nvalues + 2;
  if (comm->me == 0) {
    int size = nlist * sizeof(double);
    fwrite(&size, sizeof(int), 1, fp);
    fwrite(list, sizeof(double), nlist, fp);
  }
}

void FixMdgranChain::restart(char *buf)
{
  // the block begins with this fix's mark and the count of values after it: a block of
  // another fix or format, or one written with (without) a drive that this fix lacks (has),
  // is refused rather than read past its end
  auto head = (double *) buf;
  if (head[0] != RESTART_MARK)
    error->all(FLERR, "fix mdgran/chain: the restart file's block for this fix was not written "
               "by this version of it; start the run again from its input");
  const int expected = driven ? 7 : 5;
  if ((int) head[1] != expected)
    error->all(FLERR, "fix mdgran/chain: the restart file's block holds {} values, this fix "
               "needs {} (it was written {} a pulse or base motion)", (int) head[1], expected,
               expected == 7 ? "without" : "with");
  auto list = head + 2;
  d_hyst_all = list[0];
  d_visc_all = list[1];
  power_prev = comm->me == 0 ? list[2] : 0.0;    // rank 0 holds the sum over the ranks
  last_step = (bigint) list[3];
  have_last = (int) list[4];
  d_hyst = d_visc = 0.0;
  if (driven) {    // written with the same fix command
    work_all = list[5];
    work_prev = comm->me == 0 ? list[6] : 0.0;
    work = 0.0;
  }
}

int FixMdgranChain::pack_forward_comm(int n, int *list, double *buf, int /*pbc_flag*/,
                                      int * /*pbc*/)
{
  int m = 0;
  for (int k = 0; k < n; k++) {
    int j = list[k];
    buf[m++] = x0[j];
    buf[m++] = closed[j];
    buf[m++] = aprev[j];
    if (located) {
      buf[m++] = xs[j];
      buf[m++] = vs[j];
    }
  }
  return m;
}

void FixMdgranChain::unpack_forward_comm(int n, int first, double *buf)
{
  int m = 0;
  for (int i = first; i < first + n; i++) {
    x0[i] = buf[m++];
    closed[i] = buf[m++];
    aprev[i] = buf[m++];
    if (located) {
      xs[i] = buf[m++];
      vs[i] = buf[m++];
    }
  }
}

double FixMdgranChain::memory_usage()
{
  return (double) atom->nmax * NEXCHANGE * sizeof(double) +
      nmax_scratch * (4 * sizeof(double) + sizeof(int)) +
      (ev_all.size() + ev_local.size()) * sizeof(Event) + tab_coef.size() * sizeof(double);
}
