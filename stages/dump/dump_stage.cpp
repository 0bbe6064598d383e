#include "stages/dump/dump_stage.hpp"

#include "formats/chains/chain_store.hpp"

#include <iostream>

namespace tigerlod::dump {

void DumpStage::add_args(ArgSet& args)
{
    args.positional("INPUT", &m_input, "a chain store (.tlc)");
}

int DumpStage::run(const StageContext&)
{
    std::cout << chains::to_text(chains::read(m_input));
    return exit_ok;
}

} // namespace tigerlod::dump
