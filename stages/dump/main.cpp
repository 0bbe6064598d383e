#include "stages/dump/dump_stage.hpp"

int main(int argc, char** argv)
{
    return tigerlod::run_stage<tigerlod::dump::DumpStage>(argc, argv);
}
