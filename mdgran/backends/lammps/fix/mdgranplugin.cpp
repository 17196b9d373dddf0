// mdgran: registration of fix mdgran/chain as a LAMMPS plugin ("plugin load mdgranplugin.so").
// Built by mdgran/backends/lammps/plugin.py, which defines MDGRAN_LAMMPS_VERSION (the version string of
// the LAMMPS whose headers it compiled against, e.g. "22 Jul 2025").
#include "lammpsplugin.h"

#include "fix_mdgran_chain.h"
#include "lammps.h"
#include "modify.h"

using namespace LAMMPS_NS;

static Fix *mdgran_chain_creator(LAMMPS *lmp, int argc, char **argv)
{
  return new FixMdgranChain(lmp, argc, argv);
}

extern "C" void lammpsplugin_init(void *lmp, void *handle, void *regfunc)
{
  lammpsplugin_t plugin;
  auto register_plugin = (lammpsplugin_regfunc) regfunc;
  plugin.version = MDGRAN_LAMMPS_VERSION;
  plugin.style = "fix";
  plugin.name = "mdgran/chain";
  plugin.info = "mdgran/chain: hysteretic Schwarz/JKR/DMT/Hertz contact of a 1-D chain by tag";
  plugin.author = "mdgran";
  plugin.creator.v2 = (lammpsplugin_factory2 *) &mdgran_chain_creator;
  plugin.handle = handle;
  (*register_plugin)(&plugin, lmp);
}

// Version the plugin was compiled for: mdgran/backends/lammps/plugin.py compares it with the LAMMPS that
// loads it (LAMMPS itself only prints a note on a mismatch, and the class layouts may differ).
extern "C" const char *mdgran_plugin_lammps_version() { return MDGRAN_LAMMPS_VERSION; }

// Rows first .. first + count - 1 of the event table of the fix mdgran/chain with ID fix_id of
// the LAMMPS instance lmp (the library interface's handle) into out, 4 doubles a row (time,
// contact, kind, step), in one call (FixMdgranChain::copy_events; collective on several
// ranks), and with release != 0 every row before first + count released (drop_events).
// Returns the rows copied; -1 if fix_id is not a fix mdgran/chain or first was released.
extern "C" int mdgran_chain_events(void *lmp, const char *fix_id, int first, int count,
                                   double *out, int release)
{
  Fix *fix = static_cast<LAMMPS *>(lmp)->modify->get_fix_by_id(fix_id);
  auto *chain = dynamic_cast<FixMdgranChain *>(fix);
  if (!chain) return -1;
  const int got = chain->copy_events(first, count, out);
  if (got >= 0 && release) chain->drop_events(first + got);
  return got;
}
