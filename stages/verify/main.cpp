#include "stages/verify/verify_stage.hpp"

int main(int argc, char** argv)
{
    return tigerlod::run_stage<tigerlod::verify::VerifyStage>(argc, argv);
}
