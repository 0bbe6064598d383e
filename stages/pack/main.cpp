#include "stages/pack/pack_stage.hpp"

int main(int argc, char** argv)
{
    return tigerlod::run_stage<tigerlod::pack::PackStage>(argc, argv);
}
