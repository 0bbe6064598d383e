#include "stages/color/color_stage.hpp"

int main(int argc, char** argv)
{
    return tigerlod::run_stage<tigerlod::color::ColorStage>(argc, argv);
}
