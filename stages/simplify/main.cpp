#include "stages/simplify/simplify_stage.hpp"

int main(int argc, char** argv)
{
    return tigerlod::run_stage<tigerlod::simplify::SimplifyStage>(argc, argv);
}
