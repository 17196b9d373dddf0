// mdgran: fix mdgran/chain, the hysteretic adhesive contact of a 1-D bead chain, in C++.
//
// The native twin of the Python hook of mdgran/backends/lammps.py (fix external pf/callback):
// same law, same step-quantized switching, same floating-point operations in the same order,
// so that the two agree to round-off.  Units: mdgran's nondimensional ones through LAMMPS "lj"
// units (../../../shared/physics.md section 1): bead mass 1, length p, force eta = pi R w,
// time 1/q, energy eta p.
//
//   fix ID all mdgran/chain keyword value ...
//     law schwarz|jkr|dmt|hertz   (schwarz)      fc value | lambda value  (lambda 0.64)
//     snap_off displacement|force (displacement) damping c   k1 k   k3 k   gap g   (all 0)
//     walls yes|no (no: tags 1 and N are fixed walls)   table FILE (default: exact law)
//     closed yes|no (initial state of every contact; yes unless gap > 0)
//
// Contacts by tag: contact k joins the atoms with tags k and k+1 (found with atom->map, so
// sorting and migration do not matter); compression delta_k = u_k - u_(k+1) - gap with
// u = x - x0 the displacement from the atom's initial x (walls: u = 0, v = 0).
//
// Law (physics.md section 2, mdgran/contact.py), with t = sqrt(a) on the attached branch
// t >= t_min = sigma^(1/3), s = (fc + 2)/3, sigma = sqrt(s):
//     delta(t) = t^4 - 4 sigma t,   f(t) = fc + (t^3 - 3 sigma)^2        (Schwarz; JKR fc = -1.5,
//     V(delta) = P(t) - P(t0),      P' = f delta',  t0 = (4 sigma)^(1/3)  DMT fc = -2)
//     f = delta_+^(3/2),  V = (2/5) delta_+^(5/2)                          (Hertz)
// t(delta) by Newton on sqrt(delta - delta_min) (contact.py t_of_delta), or, with "table", the
// not-a-knot cubic spline in w = sqrt(delta - delta_min) written by mdgran.contact.ContactTable.
// fc from lambda: alpha = (1 - exp(-lambda/0.924))/1.02, fc = -6/(alpha^2 + 3).
//
// Per step (post_force; hysteresis step-quantized as in the hook):
//   * a closed contact with delta <= delta_off opens (V(delta) goes to D_hysteresis), an open
//     one with delta >= 0 closes; strict inequalities where delta_off = 0 (DMT, Hertz).
//     delta_off = delta_min (snap_off displacement) or delta at f = fc (snap_off force).
//     Event time: linear interpolation of delta between the previous step and this one.
//   * force of a closed contact F = f(delta) + c d(delta)/dt (0 when open), pushing the right
//     atom by +F and the left one by -F; plus the cubic substrate -k3 u^3 on every atom.  The
//     linear substrate -k1 u is fix spring/self's; k1 is given here only for the estimate below.
//   * post_force sees v(t + dt/2): the damping rate uses v(t + dt) ~ v(t + dt/2) + dt/2 a(t),
//     a(t) = contact + cubic + linear substrate force of the previous step (mass 1).
//   * a second call for the same step (the set-up of a "run") recomputes the force and
//     advances nothing.
//   * D_viscous: trapezoidal integral of the damping power c sum (d delta/dt)^2.
//
// Output: scalar = contact energy sum V (fix_modify energy yes puts it into pe); vector =
// [D_hysteresis, D_viscous, number of events]; array = events [time, contact number (1..n+1
// with walls, 2..n without), kind (1 close, 0 open), step]; per-atom vector = state of the
// contact to the atom's right (1 closed).  With several MPI ranks each contact is owned by
// the rank owning its left atom (events and dissipation there); the rank owning the right atom
// repeats the same update on a ghost copy of the state (forward-communicated every step with
// x0 and a(t)), so both agree; comm_modify vel yes and a ghost cut-off above the largest
// |x_(k+1) - x_k| of a closed contact are needed.  Sums over ranks are synced at set-up and at
// the end of every run, and when a global output is asked for (thermo, extract_fix).
#include "fix_mdgran_chain.h"

#include "atom.h"
#include "comm.h"
#include "domain.h"
#include "error.h"
#include "memory.h"
#include "update.h"
#include "utils.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>

using namespace LAMMPS_NS;
using namespace FixConst;

static constexpr int NEWTON_STEPS = 7;    // as mdgran/contact.py
static constexpr int NPERATOM = 4;        // x0, closed, dprev, aprev

FixMdgranChain::FixMdgranChain(LAMMPS *lmp, int narg, char **arg) :
    Fix(lmp, narg, arg), x0(nullptr), closed(nullptr), dprev(nullptr), aprev(nullptr),
    fcon(nullptr), u(nullptr), w(nullptr), left(nullptr), nmax_scratch(0)
{
  hertz = 0;
  fc = 0.0;
  double lambda = 0.64;
  int fc_given = 0, init_closed = -1;
  snap_force = 0;
  damping = k1 = k3 = gap = 0.0;
  walls = 0;
  use_table = 0;
  for (int iarg = 3; iarg < narg; iarg += 2) {
    if (iarg + 1 >= narg)
      error->all(FLERR, "fix mdgran/chain: keyword {} needs a value", arg[iarg]);
    std::string key = arg[iarg], val = arg[iarg + 1];
    if (key == "law") {
      if (val == "hertz") hertz = 1;
      else if (val == "jkr") { fc = -1.5; fc_given = 1; }
      else if (val == "dmt") { fc = -2.0; fc_given = 1; }
      else if (val != "schwarz") error->all(FLERR, "fix mdgran/chain: unknown law {}", val);
    } else if (key == "fc") { fc = utils::numeric(FLERR, val, false, lmp); fc_given = 1; }
    else if (key == "lambda") lambda = utils::numeric(FLERR, val, false, lmp);
    else if (key == "snap_off") {
      if (val == "force") snap_force = 1;
      else if (val != "displacement") error->all(FLERR, "fix mdgran/chain: snap_off {}?", val);
    } else if (key == "damping") damping = utils::numeric(FLERR, val, false, lmp);
    else if (key == "k1") k1 = utils::numeric(FLERR, val, false, lmp);
    else if (key == "k3") k3 = utils::numeric(FLERR, val, false, lmp);
    else if (key == "gap") gap = utils::numeric(FLERR, val, false, lmp);
    else if (key == "walls") walls = utils::logical(FLERR, val, false, lmp);
    else if (key == "closed") init_closed = utils::logical(FLERR, val, false, lmp);
    else if (key == "table") { use_table = 1; table_file = val; }
    else error->all(FLERR, "fix mdgran/chain: unknown keyword {}", key);
  }
  if (!hertz && !fc_given) {
    double alpha = (1.0 - std::exp(-lambda / 0.924)) / 1.02;
    fc = -6.0 / (alpha * alpha + 3.0);
  }
  if (!hertz && !(fc >= -2.0 && fc <= -1.5))
    error->all(FLERR, "fix mdgran/chain: fc must lie in [-2, -1.5], not {}", fc);

  // constants of the law, evaluated as mdgran/contact.py does (same libm calls)
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
  if (use_table) read_table(table_file.c_str());
  if (init_closed < 0) init_closed = gap <= 0.0;

  if (atom->map_style == Atom::MAP_NONE)
    error->all(FLERR, "fix mdgran/chain needs an atom map (atom_modify map array)");
  if (domain->xperiodic) error->all(FLERR, "fix mdgran/chain: x must not be periodic");

  scalar_flag = 1;
  extscalar = 1;
  energy_global_flag = 1;
  vector_flag = 1;
  size_vector = 3;
  extvector = 1;
  array_flag = 1;
  size_array_rows = 0;
  size_array_cols = 4;
  size_array_rows_variable = 1;
  extarray = 0;
  global_freq = 1;
  peratom_flag = 1;
  size_peratom_cols = 0;
  peratom_freq = 1;
  restart_global = 1;
  restart_peratom = 1;
  comm_forward = 3;
  maxexchange = NPERATOM;

  ntags = (tagint) atom->natoms;
  grow_arrays(atom->nmax);
  atom->add_callback(Atom::GROW);
  atom->add_callback(Atom::RESTART);
  double **x = atom->x;
  for (int i = 0; i < atom->nlocal; i++) {
    x0[i] = x[i][0];
    closed[i] = (init_closed && atom->tag[i] < (tagint) atom->natoms) ? 1.0 : 0.0;
    dprev[i] = aprev[i] = 0.0;
  }
  last_step = 0;
  have_last = 0;
  power_prev = d_hyst = d_visc = d_hyst_all = d_visc_all = 0.0;
  synced_step = -1;
  ncompute = 0;
  energy_at = -1;
  energy_cache = 0.0;
}

FixMdgranChain::~FixMdgranChain()
{
  if (copymode) return;
  atom->delete_callback(id, Atom::GROW);
  atom->delete_callback(id, Atom::RESTART);
  memory->destroy(x0);
  memory->destroy(closed);
  memory->destroy(dprev);
  memory->destroy(aprev);
  memory->destroy(fcon);
  memory->destroy(u);
  memory->destroy(w);
  memory->destroy(left);
}

int FixMdgranChain::setmask()
{
  return POST_FORCE;
}

void FixMdgranChain::init()
{
  if (comm->nprocs > 1 && !comm->ghost_velocity)
    error->all(FLERR, "fix mdgran/chain on several ranks needs comm_modify vel yes");
  if (atom->natoms > MAXSMALLINT) error->all(FLERR, "fix mdgran/chain: too many atoms");
}

// ---- the law ------------------------------------------------------------------------------

// Branch parameter t >= t_min with t^4 - 4 sigma t = delta: Newton on
// phi(w) = w sqrt(w^2 + 4 tm w + 6 tm^2) = sqrt(delta - delta_min), w = t - tm, from above.
double FixMdgranChain::t_of_delta(double d) const
{
  double rhs = std::sqrt(std::max(d - delta_min, 0.0));
  if (tm == 0.0) return std::sqrt(rhs);    // DMT: phi(w) = w^2
  double w = std::min(rhs / sqrt_big, std::sqrt(rhs));
  for (int it = 0; it < NEWTON_STEPS; it++) {
    double sq = std::sqrt(w * w + 4.0 * tm * w + big);
    w = w - (w * sq - rhs) / (sq + w * (w + 2.0 * tm) / sq);
  }
  return tm + std::max(w, 0.0);
}

double FixMdgranChain::exact_force(double d) const
{
  if (hertz) {
    double dp = std::max(d, 0.0);
    return dp * std::sqrt(dp);
  }
  double u = std::pow(t_of_delta(d), 3.0) - 3.0 * sigma;
  return fc + u * u;
}

double FixMdgranChain::law_force(double d) const
{
  return use_table ? spline_force(d) : exact_force(d);
}

// antiderivative of f(t) delta'(t): V(delta) = P(t(delta)) - P(t0)
double FixMdgranChain::antiderivative(double t) const
{
  const double sg = sigma;
  return 0.4 * std::pow(t, 10.0) - 4.0 * sg * std::pow(t, 7.0) +
      (fc + 15.0 * sg * sg) * std::pow(t, 4.0) - 4.0 * sg * (fc + 9.0 * sg * sg) * t;
}

double FixMdgranChain::law_energy(double d) const
{
  if (hertz) {
    double dp = std::max(d, 0.0);
    return 0.4 * dp * dp * std::sqrt(dp);
  }
  return antiderivative(t_of_delta(d)) - antiderivative(t0);
}

// The spline table of mdgran.contact.ContactTable.write_spline: keyword lines, then the
// (n - 1) x 4 coefficients of the force, every number with 17 digits (exact round trip).
void FixMdgranChain::read_table(const char *file)
{
  std::ifstream in(file);
  if (!in) error->one(FLERR, "fix mdgran/chain: cannot open table {}", file);
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
  if (tab_n < 2) error->one(FLERR, "fix mdgran/chain: table {} has no 'n' line", file);
  tab_coef.resize(4 * (size_t) (tab_n - 1));
  std::string tok;
  for (size_t k = 0; k < tab_coef.size(); k++) {
    if (!(in >> tok)) error->one(FLERR, "fix mdgran/chain: table {} is truncated", file);
    tab_coef[k] = std::strtod(tok.c_str(), nullptr);
  }
}

// ---- the step -----------------------------------------------------------------------------

inline double FixMdgranChain::disp(int i) const
{
  return is_wall(atom->tag[i]) ? 0.0 : atom->x[i][0] - x0[i];
}

void FixMdgranChain::setup(int vflag)
{
  post_force(vflag);
  sync();
}

void FixMdgranChain::post_force(int /*vflag*/)
{
  compute(update->ntimestep);
}

void FixMdgranChain::compute(bigint step)
{
  const int new_step = !have_last || step != last_step;
  ncompute++;
  comm->forward_comm(this);    // ghosts get x0, state and a(t) of their owners
  const int nlocal = atom->nlocal, nall = nlocal + atom->nghost;
  if (nall > nmax_scratch) {
    nmax_scratch = atom->nmax;
    memory->destroy(fcon);
    memory->destroy(u);
    memory->destroy(w);
    memory->destroy(left);
    memory->create(fcon, nmax_scratch, "mdgran/chain:fcon");
    memory->create(u, nmax_scratch, "mdgran/chain:u");
    memory->create(w, nmax_scratch, "mdgran/chain:w");
    memory->create(left, nmax_scratch, "mdgran/chain:left");
  }
  tagint *tag = atom->tag;
  double **x = atom->x, **v = atom->v;
  const tagint natoms = ntags = (tagint) atom->natoms;
  const double dt = update->dt;
  const double t = (double) step * dt;
  const int use_est = step > 0 && have_last;
  const int nprocs = comm->nprocs;
  // tag -> local index: the map array directly where there is one (atom->map() is virtual)
  const int *mapa = atom->map_style == Atom::MAP_ARRAY ? atom->get_map_array() : nullptr;
  auto find = [&](tagint k) { return mapa ? mapa[k] : atom->map(k); };
  double power = 0.0;
  std::vector<Event> found;    // events of this step with their lost energy
  std::vector<double> lost;

  // 0. displacement u = x - x0 and velocity estimate w of every atom, owned and ghost
  for (int i = 0; i < nall; i++) {
    if (is_wall(tag[i])) {
      u[i] = w[i] = 0.0;
    } else {
      u[i] = x[i][0] - x0[i];
      w[i] = use_est ? v[i][0] + 0.5 * dt * aprev[i] : v[i][0];
    }
  }

  // a switch of contact l at this step (rare): its event time and lost energy, on the owner
  auto record = [&](int l, double delta, int opening) __attribute__((noinline)) {
    double prev = have_last ? dprev[l] : delta;
    double thr = opening ? delta_off : 0.0;
    double span = prev - delta;
    double frac = span != 0.0 ? (prev - thr) / span : 1.0;
    double te = step > 0 ? t - dt + std::min(std::max(frac, 0.0), 1.0) * dt : t;
    found.push_back({step, tag[l], opening ? 0 : 1, te});
    lost.push_back(opening ? law_energy(delta) : 0.0);
  };
  auto overflow = [&](int l, double delta) __attribute__((noinline)) {
    error->one(FLERR,
               "compression {:.4g} beyond the contact table (delta_max = {:g}) at t = {:.12g}, "
               "contact {}", delta, tab_delta_max, t, contact_number(tag[l]));
  };
  // one contact (left atom l, right atom r): state update at a new step, then its force
  auto contact = [&](int l, int r, int own) __attribute__((always_inline)) {
    double delta = u[l] - u[r];
    if (gap != 0.0) delta = delta - gap;
    double rate = w[l] - w[r];
    if (new_step) {
      int c = closed[l] != 0.0;
      int opening = c && (strict ? delta < 0.0 : delta <= delta_off);
      int closing = !c && (strict ? delta > 0.0 : delta >= 0.0);
      if (opening || closing) {
        if (own) record(l, delta, opening);
        closed[l] = opening ? 0.0 : 1.0;
      }
      if (own) dprev[l] = delta;
    }
    if (use_table && delta > tab_delta_max) overflow(l, delta);
    double F = 0.0;
    if (closed[l] != 0.0) {
      F = use_table ? spline_force(delta) : exact_force(delta);
      if (damping != 0.0) F = F + damping * rate;
      if (own && new_step && damping != 0.0) power += rate * rate;
    }
    fcon[l] = F;
  };

  // 1. contacts owned here (left atom owned); note each owned right atom's left neighbour
  for (int i = 0; i < nlocal; i++) left[i] = -1;
  for (int i = 0; i < nlocal; i++) {
    fcon[i] = 0.0;
    if (tag[i] >= natoms) continue;    // last atom: no contact to its right
    int j = find(tag[i] + 1);
    if (j < 0) {    // partner beyond the ghost cut-off: fine only for an open contact
      if (closed[i] != 0.0)
        error->one(FLERR, "fix mdgran/chain: contact {} is closed but atom {} is beyond the "
                   "ghost cut-off (raise comm_modify cutoff)", contact_number(tag[i]), tag[i] + 1);
      continue;
    }
    if (j < nlocal) left[j] = i;
    contact(i, j, 1);
  }
  // 2. contacts whose left atom is a ghost and right atom owned: the same update on the copy
  for (int i = 0; i < nlocal; i++) {
    if (left[i] >= 0 || tag[i] <= 1) continue;
    int l = find(tag[i] - 1);
    left[i] = l;    // -1: beyond the cut-off, so open (its owner checks)
    if (l >= nlocal) contact(l, i, 0);
  }
  // 3. forces on owned atoms: x'' = F_left - F_right - k3 u^3 (- k1 u by fix spring/self)
  double **f = atom->f;
  int *mask = atom->mask;
  for (int i = 0; i < nlocal; i++) {
    double ext = 0.0;
    if (!is_wall(tag[i])) {
      double fl = left[i] >= 0 ? fcon[left[i]] : 0.0;
      ext = (0.0 - fcon[i]) + fl;
      if (k3 != 0.0) ext = ext - k3 * std::pow(u[i], 3.0);
    }
    if (!std::isfinite(ext))
      error->one(FLERR, "non-finite force at t = {:.12g}, bead {}", t, walls ? tag[i] - 1 : tag[i]);
    if (mask[i] & groupbit) f[i][0] += ext;
    if (new_step) aprev[i] = k1 != 0.0 ? ext - k1 * u[i] : ext;
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
  if (have_last) {
    double dv = 0.5 * (power + power_prev) * dt;
    if (nprocs == 1) d_visc_all += dv;
    else d_visc += dv;
  }
  power_prev = power;
  last_step = step;
  have_last = 1;
  size_array_rows = (int) ev_all.size();
}

// sums over ranks and the event list gathered on every rank (collective)
void FixMdgranChain::sync()
{
  if (comm->nprocs == 1) return;
  synced_step = update->ntimestep;
  double part[2] = {d_hyst, d_visc}, sum[2];
  MPI_Allreduce(part, sum, 2, MPI_DOUBLE, MPI_SUM, world);
  d_hyst_all += sum[0];
  d_visc_all += sum[1];
  d_hyst = d_visc = 0.0;
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
  std::sort(got.begin(), got.end(), [](const Event &a, const Event &b) {
    return a.step != b.step ? a.step < b.step : a.left < b.left;
  });
  ev_all.insert(ev_all.end(), got.begin(), got.end());
  ev_local.clear();
  size_array_rows = (int) ev_all.size();
}

void FixMdgranChain::post_run()
{
  sync();
}

// ---- output -------------------------------------------------------------------------------

double FixMdgranChain::compute_scalar()
{
  if (energy_at == ncompute) return energy_cache;    // positions unchanged since then
  double e = 0.0;
  const int nlocal = atom->nlocal;
  ntags = (tagint) atom->natoms;
  for (int i = 0; i < nlocal; i++) {
    if (closed[i] == 0.0 || atom->tag[i] >= (tagint) atom->natoms) continue;
    int j = atom->map(atom->tag[i] + 1);
    if (j < 0) continue;
    double delta = disp(i) - disp(j);
    if (gap != 0.0) delta = delta - gap;
    e += law_energy(delta);
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
  return (double) ev_all.size();
}

double FixMdgranChain::compute_array(int row, int col)
{
  if (comm->nprocs > 1 && synced_step != update->ntimestep) sync();
  if (row < 0 || row >= (int) ev_all.size()) return 0.0;
  const Event &e = ev_all[row];
  if (col == 0) return e.time;
  if (col == 1) return (double) contact_number(e.left);
  if (col == 2) return (double) e.kind;
  return (double) e.step;
}

// ---- per-atom state: growth, migration, restart, ghosts ---------------------------------

void FixMdgranChain::grow_arrays(int nmax)
{
  memory->grow(x0, nmax, "mdgran/chain:x0");
  memory->grow(closed, nmax, "mdgran/chain:closed");
  memory->grow(dprev, nmax, "mdgran/chain:dprev");
  memory->grow(aprev, nmax, "mdgran/chain:aprev");
  vector_atom = closed;
}

void FixMdgranChain::copy_arrays(int i, int j, int /*delflag*/)
{
  x0[j] = x0[i];
  closed[j] = closed[i];
  dprev[j] = dprev[i];
  aprev[j] = aprev[i];
}

int FixMdgranChain::pack_exchange(int i, double *buf)
{
  buf[0] = x0[i];
  buf[1] = closed[i];
  buf[2] = dprev[i];
  buf[3] = aprev[i];
  return NPERATOM;
}

int FixMdgranChain::unpack_exchange(int nlocal, double *buf)
{
  x0[nlocal] = buf[0];
  closed[nlocal] = buf[1];
  dprev[nlocal] = buf[2];
  aprev[nlocal] = buf[3];
  return NPERATOM;
}

int FixMdgranChain::pack_restart(int i, double *buf)
{
  buf[0] = NPERATOM + 1;    // values of this fix, this count included
  pack_exchange(i, &buf[1]);
  return NPERATOM + 1;
}

void FixMdgranChain::unpack_restart(int nlocal, int nth)
{
  double **extra = atom->extra;
  int m = 0;    // skip the values of the fixes stored before this one
  for (int k = 0; k < nth; k++) m += static_cast<int>(extra[nlocal][m]);
  unpack_exchange(nlocal, &extra[nlocal][m + 1]);
}

int FixMdgranChain::size_restart(int /*nlocal*/)
{
  return NPERATOM + 1;
}

int FixMdgranChain::maxsize_restart()
{
  return NPERATOM + 1;
}

// global state: totals of this rank (rank 0 writes; every rank reads, rank 0 keeps the sums)
void FixMdgranChain::write_restart(FILE *fp)
{
  double list[5] = {d_hyst_all + d_hyst, d_visc_all + d_visc, power_prev, (double) last_step,
                    (double) have_last};
  if (comm->me == 0) {
    int size = sizeof(list);
    fwrite(&size, sizeof(int), 1, fp);
    fwrite(list, sizeof(double), 5, fp);
  }
}

void FixMdgranChain::restart(char *buf)
{
  auto list = (double *) buf;
  d_hyst_all = list[0];
  d_visc_all = list[1];
  power_prev = comm->me == 0 ? list[2] : 0.0;    // summed over ranks at the next step
  last_step = (bigint) list[3];
  have_last = (int) list[4];
  d_hyst = d_visc = 0.0;
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
  }
}

double FixMdgranChain::memory_usage()
{
  return (double) atom->nmax * NPERATOM * sizeof(double) +
      nmax_scratch * (3 * sizeof(double) + sizeof(int)) +
      (ev_all.size() + ev_local.size()) * sizeof(Event) + tab_coef.size() * sizeof(double);
}
