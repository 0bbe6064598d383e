#include "stages/serve/serve_stage.hpp"

int main(int argc, char** argv)
{
    return tigerlod::run_stage<tigerlod::serve::ServeStage>(argc, argv);
}
