#include "stages/render/render_stage.hpp"

int main(int argc, char** argv)
{
    return tigerlod::run_stage<tigerlod::render::RenderStage>(argc, argv);
}
