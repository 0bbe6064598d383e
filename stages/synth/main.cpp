#include "stages/synth/synth_stage.hpp"

int main(int argc, char** argv)
{
    return tigerlod::run_stage<tigerlod::synth::SynthStage>(argc, argv);
}
